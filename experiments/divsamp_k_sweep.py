"""K sweep of a trained DivSamp model (the paper's Fig. 6b): APD, ADE, FDE against the number of samples K.

    flock /tmp/jaxmotion-heavy.lock python experiments/divsamp_k_sweep.py \
        --config experiments/configs/divsamp_bandai.py --data ../shared/data/bandai-namco-2 \
        --workdir /tmp/runs/divsamp_bandai --windows 200

One trained sampler serves every K (K is a call argument). All K are measured on the same evenly
spaced subset of `--windows` test windows (drawing K = 1000 futures for all 1,609 Bandai windows
would cost 1.6 M decoder passes); the multimodal ground truth still comes from all test windows.
The CVAE sampled from N(0, I) is measured alongside. Writes `<out>.json` and `<out>.png`.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.train.compile_time import CompileTimer
from jaxmotion.config import load_config
from jaxmotion.eval import evaluate_windows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True)
    p.add_argument("--data", default=None)
    p.add_argument("--workdir", required=True, help="folder trained by `jaxmotion train` (cvae/, sampler/)")
    p.add_argument("--ks", type=int, nargs="+", default=[2, 5, 10, 50, 100, 1000])
    p.add_argument("--windows", type=int, default=200, help="evenly spaced test windows used for every K")
    p.add_argument("--methods", nargs="+", default=["divsamp", "divsamp_cvae"])
    p.add_argument("--out", default="experiments/results/divsamp_k_sweep_bandai")
    args = p.parse_args(argv)
    if any(k < 2 for k in args.ks):
        raise SystemExit(f"--ks: every K must be >= 2, got {args.ks}")

    cfg = load_config(args.config)
    ds = experiment.load_data(cfg, args.data)
    full = experiment.prepare(ds)
    sub = experiment.prepare(ds, args.windows)
    params = experiment.restore(cfg, full, Path(args.workdir))
    rows = []
    for name in args.methods:
        for k in args.ks:
            rec = sweep_point(cfg, ds, params, full, sub, name, k)
            rows.append(rec)
            print(json.dumps(rec), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"dataset": ds.name, "config": args.config, "windows": [int(i) for i in sub.keep],
            "n_test_windows": int(len(full.x)), "seed": cfg.seed, "jax_version": jax.__version__}
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    plot(rows, out.with_suffix(".png"), f"{ds.name}: {len(sub.x)} of {len(full.x)} test windows (evenly spaced)")
    print(f"wrote {out.with_suffix('.json')} and {out.with_suffix('.png')}")


def sweep_point(cfg, ds, params, full: experiment.Prepared, sub: experiment.Prepared, name: str, k: int) -> dict:
    """Returns one row of the sweep: predictor `name`'s K futures of the `sub` windows, with MM sets over all `full` test windows.

    `wall_s` covers sampling and metrics; `compile_s`, the part of it spent compiling (`CompileTimer`).
    """
    fn = experiment.predictors(cfg, ds, params, k)[name]
    batch = max(1, min(cfg.eval_batch, 8000 // k))  # bounds memory at large K
    t0 = time.perf_counter()
    with CompileTimer() as compiling:
        chunks = experiment.predict_chunks(fn, sub.x, jax.random.key(cfg.seed + 7), batch)
        m = evaluate_windows(
            chunks, sub.y, sub.x[:, -1], thr=ds.mm_threshold,
            reference_last_poses=full.x[:, -1], reference_futures=full.y,
        )
    return {"method": name, "K": k, "n_windows": len(sub.x), "wall_s": round(time.perf_counter() - t0, 2),
            "compile_s": round(compiling.seconds, 2), **{key: float(m[key]) for key in metrics.METRIC_NAMES}}


def plot(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for name in sorted({r["method"] for r in rows}):
        rs = sorted((r for r in rows if r["method"] == name), key=lambda r: r["K"])
        ks = [r["K"] for r in rs]
        for ax, key in zip(axes, ("APD", "ADE", "FDE")):
            ax.plot(ks, [r[key] for r in rs], "o-", label=name)
    for ax, key in zip(axes, ("APD", "ADE", "FDE")):
        ax.set_xscale("log")
        ax.set_xlabel("K (number of samples)")
        ax.set_ylabel(f"{key} (m)")
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
