"""The long-budget runs behind the README's headline and the claims table were made with the committed configs.

Each `metrics.json` record carries the config its run used. For every file in `docs/generate.LONG_RUNS` that
config must equal `experiments/configs/<its name>.py` as committed now, setting by setting, except where an
option has since been removed because one value became the only behaviour (`REMOVED`), or added with a
default that is the behaviour the run had (`ADDED`). Editing a config behind a headline run without running
it again fails here.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from jaxmotion.config import load_config, to_dict

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("docs_generate", ROOT / "docs" / "generate.py")
generate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(generate)

# Options removed once one value was all the code did: (last key, the value that survives).
REMOVED = {"dense_init": "torch", "bn_running_var": "unbiased", "test_eps": "independent"}
# Options added later, whose default is what the code did before them.
ADDED = {"dedupe_members": False, "k_protocol": "top_k", "micro_batches": 1, "split": "test", "precision": "float32",
         "train_sampler": "windows", "mm_ground_truth": None, "mm_deviation": None,
         # DivSamp's release CVAE options (off) and the settings they read; HumanMAC's lr steps and mod_test (off).
         "cvae_lambda_angle": 0.0, "cvae_pseudo_prob": 0.0, "angle_percentile": 0.1, "angle_margin": 0.05,
         "angle_bounds_frames": 20000, "mm_candidate_stride": 20, "mm_his_threshold": 0.05, "mm_pred_threshold": 0.1,
         "lr_milestones": [], "lr_gamma": 0.9, "test_cond_keep": 1.0, "batch_norm": "global",
         # MOJO's second-stage reconstruction norm (None: the one of its CVAE objective's release).
         "q_recon": None}
# Set per run on the command line (`--data`, `--seed`), or what was evaluated rather than trained (`eval_k`).
PER_RUN = {"dataset", "seed", "eval_k"}


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = json.loads(json.dumps(v))  # tuples as lists, as in the records
    return out


def config_differences(recorded: dict, committed: dict) -> list[str]:
    """Returns the settings where a run's recorded config and a committed config disagree beyond the allowances."""
    run, now = _flat(recorded), _flat(committed)
    out = []
    for key in sorted(set(run) | set(now)):
        last = key.rsplit(".", 1)[-1]
        if key.split(".", 1)[0] in PER_RUN | {"action_classifier", "angle_bounds"}:
            continue  # what the run measured about itself, not a setting
        if key not in now and last in REMOVED and run[key] == REMOVED[last]:
            continue
        if key not in run and last in ADDED and now[key] == ADDED[last]:
            continue
        if run.get(key, "<absent>") != now.get(key, "<absent>"):
            out.append(f"{key}: run {run.get(key, '<absent>')!r}, committed {now.get(key, '<absent>')!r}")
    return out


HUMANEVA_RUNS = sorted({f for *_, config, _ in generate.HUMANEVA_ROWS for f in generate.humaneva_runs(config)})
# The diagnostics of a HumanEva-I row, each with a config of its own (`sampler/` is not: its run differed from
# `mojo_vae_dct_humaneva.py` in `train_sampler` alone, as its README says).
HUMANEVA_DIAGNOSTICS = sorted(str(p.relative_to(generate.EXP)) for d in ("kld", "dlow_loss")
                              for p in (generate.EXP / "humaneva" / d).glob("*_metrics.json"))
# Runs recorded under the name their config had then, whose settings now live in a config of another name.
RECORDED_UNDER = {"humaneva/dlow_loss": "mojo_vae_dct_humaneva_dlow_loss"}


@pytest.mark.parametrize("name", generate.LONG_RUNS + HUMANEVA_RUNS + HUMANEVA_DIAGNOSTICS)
def test_a_headline_run_was_made_with_its_committed_config(name):
    recs = json.loads((generate.EXP / name).read_text())
    recorded = recs[0]["config"]
    assert all(r["config"] == recorded for r in recs), f"{name}: its records disagree on the config"
    if str(Path(name).parent) in RECORDED_UNDER:
        recorded = dict(recorded, name=RECORDED_UNDER[str(Path(name).parent)])
    path = ROOT / "experiments" / "configs" / f"{recorded['name']}.py"
    assert path.exists(), f"{name}: made with {recorded['name']!r}, which is not a committed config"
    diff = config_differences(recorded, to_dict(load_config(path)))
    assert not diff, f"{name} differs from {path.name}: " + "; ".join(diff)


def test_a_changed_setting_is_reported():
    recorded = json.loads((generate.EXP / generate.GSPS_SCALED).read_text())[0]["config"]
    committed = to_dict(load_config(ROOT / "experiments" / "configs" / "gsps_bandai_long_scaled.py"))
    assert config_differences(recorded, committed) == []
    committed["method_config"]["alpha"] = 100.0  # the Human3.6M value: another run
    committed["method_config"]["dense_init"] = "flax"  # a removed option back at another value
    recorded = json.loads(json.dumps(recorded))
    recorded["method_config"]["bn_running_var"] = "biased"  # a removed option at the value that did not survive
    assert config_differences(recorded, committed) == [
        "method_config.alpha: run 33.5, committed 100.0",
        "method_config.bn_running_var: run 'biased', committed '<absent>'",
        "method_config.dense_init: run '<absent>', committed 'flax'",
    ]
