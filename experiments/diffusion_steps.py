"""Accuracy vs sampling steps of a trained diffusion predictor: ADE, APD and the time of one K = 50 batch at 10 / 25 / 50 / 100 DDIM steps.

    flock /tmp/jaxmotion-heavy.lock python experiments/diffusion_steps.py \
        --config experiments/configs/diffusion_bandai.py --data ../shared/data/bandai-namco-2 \
        --workdir ~/jaxmotion-runs/diffusion_bandai_s0 --windows 320

One trained model serves every number of steps (`methods.diffusion.sampler`'s `sampling_steps`). Every
step count is scored on the same evenly spaced `--windows` test windows (the multimodal ground truth
from all test windows), and timed on one batch of `Config.eval_batch` windows x K futures: the median of
`--repeats` calls of the compiled sampler after one warm-up call. Writes `<out>.json` and `<out>.png`.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import jax
import numpy as np

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.config import load_config
from jaxmotion.methods.diffusion import sampler
from jaxmotion.eval import evaluate_windows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True)
    p.add_argument("--data", default=None)
    p.add_argument("--workdir", required=True, help="folder trained by `jaxmotion train` (diffusion/)")
    p.add_argument("--steps", type=int, nargs="+", default=[10, 25, 50, 100])
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--windows", type=int, default=320, help="evenly spaced test windows scored at every step count")
    p.add_argument("--repeats", type=int, default=3, help="timed calls of one batch per step count")
    p.add_argument("--out", default="experiments/results/diffusion_steps_bandai")
    args = p.parse_args(argv)

    cfg = load_config(args.config)
    ds = experiment.load_data(cfg, args.data)
    full = experiment.prepare(ds)
    sub = experiment.prepare(ds, args.windows)
    params = experiment.restore(cfg, full, Path(args.workdir))
    rows = [point(cfg, ds, params, full, sub, s, args.k, args.repeats) for s in args.steps]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"dataset": ds.name, "config": args.config, "workdir": str(args.workdir), "K": args.k,
            "n_windows": len(sub.x), "n_test_windows": int(len(full.x)), "batch": cfg.eval_batch, "seed": cfg.seed,
            "jax_version": jax.__version__, "cpu": _cpu()}
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    plot(rows, out.with_suffix(".png"), f"{ds.name}: {len(sub.x)} of {len(full.x)} test windows, K = {args.k}; "
                                        f"time: one batch of {cfg.eval_batch} windows")
    print(f"wrote {out.with_suffix('.json')} and {out.with_suffix('.png')}")


def point(cfg, ds, params, full, sub, steps: int, k: int, repeats: int) -> dict:
    """Returns the metrics of `steps` DDIM steps on the `sub` windows and the median time of one batch of K futures."""
    fn = sampler(cfg, ds, params, k, steps)
    x = np.asarray(full.x[: cfg.eval_batch])
    jax.block_until_ready(fn(x, jax.random.key(0)))  # compiles
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(x, jax.random.key(i + 1)))
        times.append(time.perf_counter() - t0)
    chunks = experiment.predict_chunks(fn, sub.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)
    m = evaluate_windows(chunks, sub.y, sub.x[:, -1], thr=ds.mm_threshold,
                                 reference_last_poses=full.x[:, -1], reference_futures=full.y)
    row = {"steps": steps, "K": k, "batch_s": statistics.median(times), "batch_times_s": times,
           **{key: float(m[key]) for key in metrics.METRIC_NAMES}}
    print(json.dumps(row), flush=True)
    return row


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            return next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor()


def plot(rows: list[dict], path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = [r["steps"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, (key, label) in zip(axes, (("ADE", "ADE (m)"), ("APD", "APD (m)"), ("batch_s", "time per batch (s)"))):
        ax.plot(s, [r[key] for r in rows], "o-")
        ax.set_xscale("log")
        ax.set_xticks(s, [str(v) for v in s])
        ax.set_xlabel("DDIM steps")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
