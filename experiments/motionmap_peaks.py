"""How many modes a trained MotionMap run predicts per test window: the peaks of its predicted maps.

    python experiments/motionmap_peaks.py ~/jaxmotion-runs/motionmap_bandai --data ../shared/data/bandai-namco-2

Counts the valid peaks of `methods.motionmap.modes_fn` (the run's own minimum peak distance and
relative threshold) on every protocol test window and prints their mean, median, range and
histogram, and the fraction of windows with at least 5 and 7 peaks (MotionMap's small-K protocols):
with fewer peaks than K, MotionMap's K futures repeat its peaks.

`--threshold-rel T [T ...]` and `--min-distance R [R ...]` count them for every combination of
other peak settings instead (`MotionMapConfig.peak_threshold_rel`, `peak_min_distance`; the maps
are the run's, only the peak extraction changes), e.g. `--threshold-rel 0.35 0.2 0.1 --min-distance 5 3`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--data", default=None, help="dataset path (default: the run's own)")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--threshold-rel", type=float, nargs="+", default=None, help="relative peak thresholds (default: the run's)")
    ap.add_argument("--min-distance", type=int, nargs="+", default=None, help="minimum peak distances in cells (default: the run's)")
    args = ap.parse_args(argv)
    if any(not 0 <= t < 1 for t in args.threshold_rel or ()) or any(r < 1 for r in args.min_distance or ()):
        ap.error("--threshold-rel values must be in [0, 1) and --min-distance values at least 1")

    from jaxmotion import experiment as ex
    from jaxmotion.methods import motionmap
    from jaxmotion.tools.predictor import run_config

    cfg, source = run_config(args.run)
    if cfg.method != "motionmap":
        ap.error(f"{args.run}: a {cfg.method!r} run, not a MotionMap one")
    ds = ex.load_data(cfg, args.data or source)
    prep = ex.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    params = ex.restore(cfg, prep, args.run)
    mc = motionmap.settings(cfg)
    for thr in args.threshold_rel or [mc.peak_threshold_rel]:
        for dist in args.min_distance or [mc.peak_min_distance]:
            c = dataclasses.replace(cfg, method_config=dataclasses.replace(mc, peak_threshold_rel=thr, peak_min_distance=dist))
            fn = motionmap.modes_fn(c, ds, params)
            counts = []
            for s in range(0, len(prep.x), args.batch):
                xb = prep.x[s : s + args.batch]
                n = len(xb)
                if n < args.batch:  # one compiled shape
                    xb = np.concatenate([xb, np.repeat(xb[-1:], args.batch - n, axis=0)])
                counts.append(np.asarray(fn(jnp.asarray(xb)).valid)[:n].sum(axis=1))
            cnt = np.concatenate(counts)
            print(f"{args.run} (threshold_rel {thr:g}, min_distance {dist}): {len(cnt)} test windows; peaks per window: "
                  f"mean {cnt.mean():.2f}, median {np.median(cnt):g}, min {cnt.min()}, max {cnt.max()}")
            print("  histogram (peaks: windows):", {int(k): int(v) for k, v in zip(*np.unique(cnt, return_counts=True))})
            print(f"  windows with >= 5 peaks: {np.mean(cnt >= 5):.3f}; >= 7 peaks: {np.mean(cnt >= 7):.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
