"""Builds the MOJO comparison table on Bandai-Namco-2 from the runs' `metrics.json` files.

    python experiments/mojo_table.py --runs /tmp/runs --out experiments/results/mojo_bandai_table

Rows: MOJO, MOJO-DCT, VAE+DCT (N(0, I) in every band), VAE+DCT+L (DLow on the lowest L bands),
DLow and zero-velocity (from the DLow run's metrics.json, the lead's shared run), all at K = 50.
Writes `<out>.md` (a markdown table) and `<out>.json` (the numbers). DLow's method module has no
realism hook, so with `--dlow-fse` the DLow rows' FSE is computed here by sampling the DLow run's
checkpoints with the evaluation's key (about a minute on 2 CPU cores; run it under the heavy lock).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

# (row label, run folder, predictor name in that run's metrics.json)
ROWS = [
    ("MOJO", "mojo_bandai", "mojo"),
    ("MOJO, N(0,I) in all bands", "mojo_bandai", "mojo_prior"),
    ("MOJO-DCT", "mojo_dct_bandai", "mojo"),
    ("VAE+DCT", "mojo_vae_dct_bandai", "mojo_prior"),
    ("VAE+DCT+L", "mojo_vae_dct_bandai", "mojo"),
    ("DLow", "dlow_bandai", "dlow"),
    ("DLow's CVAE, N(0,I)", "dlow_bandai", "cvae"),
    ("zero-velocity", "mojo_bandai", "zero_velocity"),
]
COLUMNS = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "FSE", "ADE-m", "BDF"]


def load(runs: Path, run: str, method: str, k: int = 50) -> dict | None:
    path = runs / run / "metrics.json"
    if not path.is_file():
        return None
    for rec in json.loads(path.read_text()):
        if rec["method"] == method and rec["K"] == k:
            return rec
    return None


def dlow_realism(runs: Path, data: str, k: int = 50) -> dict[str, dict[str, float]]:
    """Returns `{predictor: realism metrics}` for the DLow run's "dlow" and "cvae" samplers."""
    import jax
    import numpy as np

    from jaxmotion import experiment
    from jaxmotion.eval import realism
    from jaxmotion.config import load_config

    cfg = load_config(Path(__file__).parent / "configs" / "dlow_bandai.py")
    ds = experiment.load_data(cfg, data)
    prep = experiment.prepare(ds, cfg.max_test_windows)
    params = experiment.restore(cfg, prep, runs / "dlow_bandai")
    out = {}
    for name, fn in experiment.predictors(cfg, ds, params, k).items():
        if name not in ("dlow", "cvae"):
            continue
        parts = []
        chunks = experiment.predict_chunks(fn, prep.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)
        for i, pred in enumerate(chunks):
            s = i * cfg.eval_batch
            parts.append(realism.window_realism(pred, prep.y[s : s + pred.shape[0]], ds))
        out[name] = {key: float(np.mean(np.concatenate([p[key] for p in parts]))) for key in parts[0]}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", default="/tmp/runs")
    p.add_argument("--out", default="experiments/results/mojo_bandai_table")
    p.add_argument("--dlow-fse", action="store_true", help="compute FSE/BDF of the DLow rows from its checkpoints")
    p.add_argument("--data", default="../shared/data/bandai-namco-2")
    args = p.parse_args(argv)
    runs, out = Path(args.runs), Path(args.out)
    dlow_extra = dlow_realism(runs, args.data) if args.dlow_fse else {}
    lines = ["| method | " + " | ".join(COLUMNS) + " | run |", "| --- " * (len(COLUMNS) + 2) + "|"]
    table = []
    for label, run, method in ROWS:
        rec = load(runs, run, method)
        if rec is None:
            print(f"missing: {label} ({runs / run / 'metrics.json'}, method {method})", file=sys.stderr)
            continue
        m = dict(rec["metrics"])
        if run == "dlow_bandai":
            m.update(dlow_extra.get(method, {}))
        vals = [f"{m[c]:.3f}" if c in m else "—" for c in COLUMNS]
        lines.append(f"| {label} | " + " | ".join(vals) + f" | `{run}` / `{method}` |")
        table.append({"row": label, "run": run, "method": method, "K": rec["K"], "n_windows": rec["n_windows"],
                      **{c: m.get(c) for c in COLUMNS + ["FDE-m"]}})
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    out.with_suffix(".json").write_text(json.dumps(table, indent=1))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
