"""The `jaxmotion` command end to end on a tiny budget: run, resume after a kill, eval, sample, mismatches."""

import json
import shutil
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxmotion import experiment
from jaxmotion.cli import main
from jaxmotion.config import Config, load_config
from jaxmotion.train.runner import CheckpointMismatch

from conftest import kill_at_step

REPO = Path(__file__).resolve().parents[1]

TINY_MOJO = """
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig
def get_config():
    return Config(name="tiny_mojo", method="mojo", eval_k=(6,), max_test_windows=40, eval_batch=16,
                  method_config=MojoConfig(nz=4, nh_rnn=16, nh_mlp=(16,), num_steps=4, q_num_steps=2))
"""


def _params(cfg_path, work):
    cfg = experiment.resolve(load_config(cfg_path))
    prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
    return experiment.restore(cfg, prep, work)


def _assert_trees_equal(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(la) == len(lb) > 0
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture(scope="module")
def run_dir(tiny_cli_run):
    """`jaxmotion run` with the TINY config (tests/conftest.py): trained once per session, shared with tests/test_viewer.py."""
    return tiny_cli_run


@pytest.mark.slow
def test_run_writes_protocol_records_and_picture(run_dir):
    cfg, work = run_dir
    records = json.loads((work / "metrics.json").read_text())
    assert {(r["method"], r["K"]) for r in records} == {(m, k) for m in ("zero_velocity", "cvae", "dlow") for k in (6, 2)}
    for r in records:
        # protocol §6 (docs/pages/protocol.md#reporting) fields.
        assert set(r) >= {"dataset", "method", "K", "n_windows", "metrics", "seed", "config", "jax_version", "device", "wall_s"}
        assert r["n_windows"] == 40 and r["devices"] == 1
        assert set(r["metrics"]) >= {"APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "mode_recall"}
        assert all(np.isfinite(v) for v in r["metrics"].values() if isinstance(v, float))
        assert r["config"]["method_config_type"] == "jaxmotion.models.dlow.DLowConfig"
        assert r["config"]["method_config"]["q"]["num_steps"] == 10
    m = {(r["method"], r["K"]): r["metrics"] for r in records}
    zv = m["zero_velocity", 6]
    assert zv["APD"] == 0.0 and zv["ADE"] == zv["ADE-m"]
    # Sampled methods are stochastic: their K futures differ; the best of 6 is no worse than the best of 2 on average.
    assert m["cvae", 6]["APD"] > 0 and m["dlow", 6]["APD"] > 0
    assert m["cvae", 6]["ADE"] <= m["cvae", 2]["ADE"] + 1e-6
    png = work / "samples.png"
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    assert (work / "samples.gif").read_bytes()[:6] == b"GIF89a" and (work / "predictor.json").is_file()
    log = [json.loads(line) for line in (work / "cvae" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [10, 20, 30] and log[-1]["loss"] < log[0]["loss"]
    manifest = json.loads((work / "dlow_k6" / "stage.json").read_text())
    assert manifest["method"] == "dlow" and manifest["stage"] == "dlow_k6"


@pytest.mark.slow
def test_killed_run_resumes_to_the_uninterrupted_parameters(run_dir, tmp_path, monkeypatch):
    cfg, work = run_dir
    with pytest.raises(FileExistsError, match="--resume"):
        main(["train", "--config", str(cfg), "--workdir", str(work)])
    # Kill a second run during CVAE step 25 (checkpoints every 10 steps; the sampler's 26th call), then resume it.
    restore = kill_at_step(monkeypatch, 26)
    with pytest.raises(KeyboardInterrupt):
        main(["train", "--config", str(cfg), "--workdir", str(tmp_path / "killed")])
    restore()
    assert not (tmp_path / "killed" / "dlow_k6").exists()
    assert main(["train", "--config", str(cfg), "--workdir", str(tmp_path / "killed"), "--resume"]) == 0
    _assert_trees_equal(_params(cfg, tmp_path / "killed"), _params(cfg, work))


@pytest.mark.slow
def test_eval_reproduces_run_metrics(run_dir):
    cfg, work = run_dir
    before = json.loads((work / "metrics.json").read_text())
    assert main(["eval", "--config", str(cfg), "--workdir", str(work)]) == 0
    after = json.loads((work / "metrics.json").read_text())
    assert len(before) == len(after) == 6
    for a, b in zip(before, after):
        assert (a["method"], a["K"]) == (b["method"], b["K"])
        for key in ("APD", "ADE", "FDE", "MMADE", "MMFDE"):
            assert a["metrics"][key] == pytest.approx(b["metrics"][key], rel=1e-5)


@pytest.mark.slow
def test_sample_writes_npz_and_png(run_dir):
    cfg, work = run_dir
    assert main(["sample", "--config", str(cfg), "--workdir", str(work), "--window", "3", "--k", "6"]) == 0
    z = np.load(work / "sample_w3_dlow_k6.npz")
    assert z["preds"].shape == (6, 60, 48) and z["x"].shape == (15, 48)
    assert np.all(np.isfinite(z["preds"])) and np.abs(z["preds"][0] - z["preds"][1]).max() > 0
    prep = experiment.prepare(experiment.load_data(load_config(cfg)), 40)
    np.testing.assert_array_equal(z["x"], prep.x[3])
    assert (work / "sample_w3_dlow_k6.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(SystemExit, match="trained for K in"):
        main(["sample", "--config", str(cfg), "--workdir", str(work), "--k", "7"])


@pytest.mark.slow
def test_swapped_stage_checkpoints_are_a_clear_error(run_dir, tmp_path):
    cfg, work = run_dir
    swapped = tmp_path / "swapped"
    shutil.copytree(work, swapped)
    shutil.rmtree(swapped / "dlow_k2")
    shutil.copytree(work / "dlow_k6", swapped / "dlow_k2")
    with pytest.raises(CheckpointMismatch, match=r"stage 'dlow_k2'.*holds stage 'dlow_k6'"):
        main(["eval", "--config", str(cfg), "--workdir", str(swapped)])
    # Without the manifest the checkpoint's own shapes still give the stage away.
    (swapped / "dlow_k2" / "stage.json").unlink()
    with pytest.raises(CheckpointMismatch, match=r"stage 'dlow_k2' of method 'dlow'.*does not fit"):
        main(["eval", "--config", str(cfg), "--workdir", str(swapped)])


@pytest.mark.slow
def test_eval_of_another_methods_workdir_is_a_clear_error(run_dir, tmp_path):
    _, work = run_dir
    mojo_cfg = tmp_path / "tiny_mojo.py"
    mojo_cfg.write_text(TINY_MOJO)
    with pytest.raises(CheckpointMismatch, match=r"stage 'cvae' of method 'mojo'.*holds stage 'cvae' of method 'dlow'"):
        main(["eval", "--config", str(mojo_cfg), "--workdir", str(work)])


def test_methods_lists_the_registry(capsys):
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    for name in ("dlow", "mojo", "divsamp"):
        assert any(line.startswith(name) for line in out.splitlines())


def test_default_config_is_the_synthetic_config_file():
    assert load_config(REPO / "experiments" / "configs" / "dlow_synthetic.py") == Config()


def test_bad_config_path_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="config file not found"):
        load_config(tmp_path / "nope.py")
    bad = tmp_path / "bad.py"
    bad.write_text("x = 1\n")
    with pytest.raises(ValueError, match="get_config"):
        load_config(bad)


def test_method_config_of_the_wrong_type_is_a_clear_error():
    from jaxmotion.models.mojo import MojoConfig

    with pytest.raises(TypeError, match="method 'dlow' takes Config.method_config of type .*DLowConfig, got .*MojoConfig"):
        experiment.resolve(Config(method_config=MojoConfig()))
    with pytest.raises(ValueError, match="unknown method 'nope'; registered: .*dlow"):
        experiment.resolve(Config(method="nope"))
