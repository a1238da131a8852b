"""How many modes a trained MotionMap run predicts per test window: the peaks of its predicted maps.

    python experiments/motionmap_peaks.py ~/jaxmotion-runs/motionmap_bandai --data ../shared/data/bandai-namco-2

Counts the valid peaks of `methods.motionmap.modes_fn` (the run's own minimum peak distance and
relative threshold) on every protocol test window and prints their mean, median, range and
histogram, and the fraction of windows with at least 5 and 7 peaks (MotionMap's small-K protocols):
with fewer peaks than K, MotionMap's K futures repeat its peaks.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--data", default=None, help="dataset path (default: the run's own)")
    ap.add_argument("--batch", type=int, default=64)
    args = ap.parse_args(argv)

    from jaxmotion import experiment as ex
    from jaxmotion.methods import motionmap
    from jaxmotion.predictor import run_config

    cfg, source = run_config(args.run)
    if cfg.method != "motionmap":
        ap.error(f"{args.run}: a {cfg.method!r} run, not a MotionMap one")
    ds = ex.load_data(cfg, args.data or source)
    prep = ex.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    fn = motionmap.modes_fn(cfg, ds, ex.restore(cfg, prep, args.run))
    counts = []
    for s in range(0, len(prep.x), args.batch):
        xb = prep.x[s : s + args.batch]
        n = len(xb)
        if n < args.batch:  # one compiled shape
            xb = np.concatenate([xb, np.repeat(xb[-1:], args.batch - n, axis=0)])
        counts.append(np.asarray(fn(jnp.asarray(xb)).valid)[:n].sum(axis=1))
    c = np.concatenate(counts)
    print(f"{args.run}: {len(c)} test windows; peaks per window: mean {c.mean():.2f}, median {np.median(c):g}, "
          f"min {c.min()}, max {c.max()}")
    print("histogram (peaks: windows):", {int(k): int(v) for k, v in zip(*np.unique(c, return_counts=True))})
    print(f"windows with >= 5 peaks: {np.mean(c >= 5):.3f}; >= 7 peaks: {np.mean(c >= 7):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
