"""How multimodal MotionMap's training targets are: the peaks of the ground-truth maps, old map against a denser one.

    python experiments/motionmap_target_peaks.py ~/jaxmotion-runs/motionmap_bandai --data ../shared/data/bandai-namco-2 \
        --stride 3 --json experiments/results/motionmap_target_peaks_bandai.json

MotionMap can only predict as many modes as its heatmap model learns, and it learns maps whose
targets are Gaussian bumps at the cells of a window's multimodal futures (`gaussian_heatmap`).
This script builds those target maps for every protocol test window, its multimodal set drawn from
the training windows as in MotionMap's tables (last three observed frames, motion-transferred,
the run's threshold), and counts their peaks with the run's own peak finder and settings:

- **old map**: the run's own codebook (training windows every `pool_stride` frames, t-SNE fitted
  on `tsne_fit_points` of them, then every code transformed), members capped as in training (a
  random `max_members` of larger sets);
- **new map**: training windows every `--stride` frames (3 = 0.1 s at 30 fps, the release's
  Human3.6M candidate spacing), the run's trained autoencoder's codes of all of them, t-SNE fitted
  on every one (openTSNE, FFT gradients), members de-duplicated by cell before the same cap.

It also counts, from the data alone, how many distinct futures a window's multimodal set holds:
the futures (motion-transferred onto the window's skeleton) grouped greedily, a future joining the
first group whose leader is within `--cluster-ade` metres in ADE-term. That is what any map could
separate at best. Only the autoencoder and codebook stages of the run are needed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np


def peak_counts(cells_of_members, sets_idx, sets_mask, c, *, dedupe: bool, rng, batch: int = 64) -> np.ndarray:
    """Returns the number of peaks of each window's ground-truth map (its members' cells, capped at `c.max_members`)."""
    from jaxmotion.models import motionmap as mm

    cap = c.max_members
    draw = jax.jit(jax.vmap(lambda cl, mk: mm.gaussian_heatmap(cl.astype(jnp.float32), mk, c.hm_size, c.hm_sigma)))
    peaks = jax.jit(lambda h: mm.find_peaks(h, min_distance=c.peak_min_distance, threshold_rel=c.peak_threshold_rel, max_peaks=c.max_peaks).valid.sum(1))
    n = len(sets_idx)
    out = []
    for s in range(0, n, batch):
        cl = np.zeros((batch, cap, 2), np.int32)
        mk = np.zeros((batch, cap), bool)
        for b, w in enumerate(range(s, min(s + batch, n))):
            cells = cells_of_members[sets_idx[w, sets_mask[w]]]
            if dedupe:
                cells = np.unique(cells, axis=0)
            if len(cells) > cap:
                cells = cells[rng.choice(len(cells), cap, replace=False)]
            cl[b, : len(cells)], mk[b, : len(cells)] = cells, True
        out.append(np.asarray(peaks(draw(jnp.asarray(cl), jnp.asarray(mk)))))
    return np.concatenate(out)[:n]


def distinct_futures(futures: np.ndarray, threshold: float) -> int:
    """Returns how many groups the leader algorithm makes of `(m, t, d)` futures at ADE-term `threshold`."""
    leaders = []
    for f in futures:
        if not any(np.linalg.norm(f - g, axis=-1).mean() < threshold for g in leaders):
            leaders.append(f)
    return len(leaders)


def summary(counts: np.ndarray) -> dict:
    return {
        "mean": round(float(counts.mean()), 3), "median": float(np.median(counts)), "max": int(counts.max()),
        "share_ge_5": round(float((counts >= 5).mean()), 4), "share_ge_7": round(float((counts >= 7).mean()), 4),
        "share_1": round(float((counts == 1).mean()), 4),
        "histogram": {int(v): int(n) for v, n in zip(*np.unique(counts, return_counts=True))},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", type=Path, help="a MotionMap run folder whose autoencoder and codebook stages are trained")
    ap.add_argument("--data", default=None, help="dataset path (default: the run's own)")
    ap.add_argument("--stride", type=int, default=3, help="the new map's training-window stride in frames (default 3)")
    ap.add_argument("--cluster-ade", type=float, nargs="+", default=[0.2, 0.4], help="ADE-term thresholds (m) for distinct futures")
    ap.add_argument("--cluster-windows", type=int, default=200, help="evenly spaced test windows for the distinct-future count")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = ap.parse_args(argv)

    from jaxmotion import experiment as ex
    from jaxmotion.eval import metrics
    from jaxmotion.methods import motionmap as mmethod
    from jaxmotion.models import motionmap as mm
    from jaxmotion.tools.predictor import run_config
    from jaxmotion.train.runner import restore_untargeted

    cfg, source = run_config(args.run)
    if cfg.method != "motionmap":
        ap.error(f"{args.run}: a {cfg.method!r} run, not a MotionMap one")
    ds = ex.load_data(cfg, args.data or source)
    prep = ex.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    c = mmethod.settings(cfg)
    ae_params = restore_untargeted(args.run / "autoencoder")
    codebook = restore_untargeted(args.run / "codebook")
    ae = mm.ae_model(c, ds.dim, ds.t_his, ds.t_pred)
    enc = jax.jit(lambda y: ae.apply(ae_params, y, method=mm.MotionMapAE.encode_y))
    parents = tuple(ds.skeleton.parents)
    thr = float(c.mm_threshold if c.mm_threshold is not None else ds.mm_threshold)
    test_desc = prep.x[:, -c.descriptor_frames :]
    rng = np.random.default_rng(0)
    result = {"run": str(args.run), "n_test_windows": int(len(prep.x)), "threshold": thr,
              "peak_settings": {"min_distance": c.peak_min_distance, "threshold_rel": c.peak_threshold_rel, "hm_size": c.hm_size,
                                "sigma": c.hm_sigma, "max_members": c.max_members}}

    maps = {}
    old_pool = mmethod.Pool(prep, c)
    old_cells = np.asarray(codebook["cells"])
    if len(old_cells) != len(old_pool.windows):
        raise SystemExit(f"{args.run}: its codebook holds {len(old_cells)} futures, the data gives {len(old_pool.windows)} pool windows")
    maps["old"] = (old_pool, old_cells, False, {"pool_stride": c.pool_stride or ds.t_his, "tsne_fit_points": c.tsne_fit_points})

    new_pool = mmethod.Pool(prep, dataclasses.replace(c, pool_stride=args.stride))
    t0 = time.time()
    codes = np.concatenate([np.asarray(enc(jnp.asarray(new_pool.y[s : s + 512]))) for s in range(0, len(new_pool.y), 512)])
    pts = mm.tsne_embed(codes, fit_points=None, perplexity_fit=c.tsne_perplexity_fit, seed=cfg.seed)
    origin, scale = mm.grid_scaling(pts, c.hm_size)
    new_cells = np.asarray(mm.to_cells(jnp.asarray(pts), jnp.asarray(origin), scale, c.hm_size))
    tsne_s = time.time() - t0
    print(f"new map: {len(codes)} training windows (stride {args.stride}), t-SNE on all of them in {tsne_s:.0f} s", flush=True)
    maps["new"] = (new_pool, new_cells, True, {"pool_stride": args.stride, "tsne_fit_points": int(len(codes)), "tsne_s": round(tsne_s, 1)})

    member_sets = {}
    for name, (pool, cells, dedupe, info) in maps.items():
        sets = metrics.motionmap_mm_sets(test_desc, thr, parents, reference_desc=pool.x[:, -c.descriptor_frames :])
        idx, mask = member_sets[name] = np.asarray(sets.idx), np.asarray(sets.mask)
        members = mask.sum(1)
        distinct_cells = np.asarray([len(np.unique(cells[idx[w, mask[w]]], axis=0)) for w in range(len(idx))])
        counts = peak_counts(cells, idx, mask, c, dedupe=dedupe, rng=rng)
        result[name] = {
            **info, "n_pool": int(len(pool.windows)), "filled_cells": int(len(np.unique(cells, axis=0))),
            "members": {"mean": round(float(members.mean()), 1), "median": float(np.median(members)), "zero": int((members == 0).sum())},
            "distinct_member_cells": {"mean": round(float(distinct_cells.mean()), 1), "median": float(np.median(distinct_cells))},
            "target_peaks": summary(counts),
        }
        print(f"{name} map: {json.dumps(result[name])}", flush=True)

    # Distinct futures in the data (the new pool's members, onto each window's skeleton), on evenly spaced windows.
    pool = maps["new"][0]
    idx, mask = member_sets["new"]
    transfer = jax.jit(lambda src, tgt: mm.motion_transfer(src, tgt[None], parents))
    pick = np.linspace(0, len(idx) - 1, min(args.cluster_windows, len(idx))).round().astype(int)
    distinct = {t: [] for t in args.cluster_ade}
    for w in pick:
        m = idx[w, mask[w]]
        if len(m) == 0:
            continue
        fut = np.asarray(transfer(jnp.asarray(pool.y[m]), jnp.asarray(prep.x[w, -1])))
        for t in args.cluster_ade:
            distinct[t].append(distinct_futures(fut, t))
    result["distinct_futures"] = {f"ade_{t:g}m": summary(np.asarray(v)) for t, v in distinct.items()}
    result["distinct_futures"]["windows"] = int(len(pick))
    print(f"distinct futures: {json.dumps(result['distinct_futures'])}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
