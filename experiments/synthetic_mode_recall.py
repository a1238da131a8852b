"""Every method of the library on the synthetic data, one table of mode recall at K = 50, 6 and 5.

    flock /tmp/jaxmotion-heavy.lock python experiments/synthetic_mode_recall.py --out ~/jaxmotion-runs/synthetic_all \
        [--budget 3] [--seeds 0 1 2] [--methods dlow divsamp mojo gsps motionmap] [--markdown experiments/results/synthetic_mode_recall.md]

The synthetic data knows every test window's true futures and their probabilities (protocol §5 (docs/pages/protocol.md#marker-canonicalisation),
`jaxmotion.data.synthetic`), so mode recall (a sample reaches the true mode it is nearest to) is
exact there. Each method trains from its own synthetic config (`experiments/configs/<method>_synthetic.py`)
with every training stage's step count multiplied by `--budget` (fields whose name holds "steps",
iteration caps such as MOJO's `proj_max_steps` excepted) and `eval_k = (50, 6, 5)`; K = 6 is
MotionMap's (the data has six modes), K = 5 and 50 GSPS's table. Runs go to
`OUT/<config>_b<budget>_s<seed>` and resume (`--resume` semantics) when interrupted; the table is
rebuilt from their metrics.json files.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

CONFIGS = Path(__file__).resolve().parent / "configs"
EVAL_K = (50, 6, 5)
COLUMNS = ("APD", "ADE", "FDE", "mode_recall", "mode_recall_weighted")


def scale_steps(obj, budget: float):
    """Returns the dataclass `obj` with every training step count (a field named *steps*, not *max_steps*) times `budget`."""
    changes = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            changes[f.name] = scale_steps(v, budget)
        elif "steps" in f.name and "max_steps" not in f.name and isinstance(v, int) and v > 0:
            changes[f.name] = max(1, round(v * budget))
    return dataclasses.replace(obj, **changes)


def run_one(method: str, budget: float, seed: int, out: Path) -> Path:
    from jaxmotion import experiment as ex
    from jaxmotion.config import load_config
    from jaxmotion.methods import get_method

    cfg = load_config(CONFIGS / f"{method}_synthetic.py")
    mc = scale_steps(get_method(cfg.method).settings(cfg), budget)
    tag = f"{cfg.name}_b{budget:g}_s{seed}"
    cfg = dataclasses.replace(cfg, name=tag, method_config=mc, eval_k=EVAL_K, seed=seed)
    workdir = out / tag
    if (workdir / "metrics.json").is_file():
        print(f"{tag}: done before", flush=True)
        return workdir
    t0 = time.perf_counter()
    ds = ex.load_data(cfg)
    prep = ex.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    params = ex.train(cfg, prep, workdir, resume=workdir.exists())
    train_s = time.perf_counter() - t0
    ex.evaluate(cfg, prep, params, workdir)
    (workdir / "wall.json").write_text(json.dumps({"train_s": round(train_s, 1), "total_s": round(time.perf_counter() - t0, 1)}))
    print(f"{tag}: {time.perf_counter() - t0:.0f}s", flush=True)
    return workdir


def table(runs: list[Path]) -> str:
    import numpy as np

    rows = {}  # (K, predictor) -> list of metric dicts over seeds
    zero_seen = set()  # every run has the same zero-velocity rows: one per (K, seed)
    for run in runs:
        for r in json.loads((run / "metrics.json").read_text()):
            if r["method"] == "zero_velocity":
                if (r["K"], r["seed"]) in zero_seen:
                    continue
                zero_seen.add((r["K"], r["seed"]))
            rows.setdefault((r["K"], r["method"]), []).append(r["metrics"])
    lines = []
    for k in EVAL_K:
        lines += [f"K = {k}", "", "| predictor | seeds | " + " | ".join(COLUMNS) + " |",
                  "| --- | --- | " + " | ".join("---" for _ in COLUMNS) + " |"]
        for (kk, name), ms in sorted(rows.items()):
            if kk != k:
                continue
            cells = []
            for c in COLUMNS:
                v = np.array([m[c] for m in ms if c in m], float)
                cells.append(f"{v.mean():.3f}" + (f" ± {v.std(ddof=1):.3f}" if len(v) > 1 else "") if len(v) else "")
            lines.append(f"| {name} | {len(ms)} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--budget", type=float, default=1.0, help="multiplier of every training stage's steps")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--methods", nargs="+", default=["dlow", "divsamp", "mojo", "gsps", "motionmap"])
    ap.add_argument("--markdown", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.budget <= 0:
        ap.error(f"--budget must be > 0, got {args.budget}")
    for m in args.methods:
        if not (CONFIGS / f"{m}_synthetic.py").is_file():
            ap.error(f"no config {CONFIGS / f'{m}_synthetic.py'}")
    out = args.out.expanduser()
    runs = [run_one(m, args.budget, s, out) for s in args.seeds for m in args.methods]
    text = f"Synthetic data, budget x{args.budget:g}, seeds {args.seeds}\n\n" + table(runs)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
