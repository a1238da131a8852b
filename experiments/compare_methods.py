"""End poses of every method's K futures side by side, on the most multimodal test windows, with the true multimodal futures.

    python experiments/compare_methods.py RUN_DIR [RUN_DIR ...] --data ../shared/data/bandai-namco-2 \
        [--windows 3] [--k 50] [--out experiments/results/compare_methods_bandai.png]

Every RUN_DIR is a finished run (with `metrics.json`; its config from `predictor.run_config`) on the same data; each
contributes its method's own sampler (`--samplers NAME ...` picks others, one per run, e.g. `cvae`).
Windows: the `--windows` test windows whose multimodal ground truth (protocol §2 (docs/pages/protocol.md#metrics)) is most
spread (`experiment.most_multimodal`). One row per window; the first column overlays the end
poses (frame +t_pred) of the window's multimodal ground-truth futures, the others the K end poses of
each run, front view, the last observed pose in grey; each panel's title gives the sampler's APD
and its best-of-K final displacement on that window.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--data", default=None, help="dataset path (default: the first run's config)")
    ap.add_argument("--samplers", nargs="+", default=None, help="one sampler name per run (default: each run's method)")
    ap.add_argument("--windows", type=int, default=3)
    ap.add_argument("--k", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("experiments/results/compare_methods.png"))
    args = ap.parse_args(argv)

    from jaxmotion import experiment as ex
    from jaxmotion.eval import metrics
    from jaxmotion.tools.predictor import run_config
    from jaxmotion.pictures.viz import draw_pose, frames_to_joints, view_axes, plt

    if args.samplers is not None and len(args.samplers) != len(args.runs):
        ap.error(f"--samplers needs one name per run ({len(args.runs)}), got {len(args.samplers)}")
    cfgs, sources = [], []
    for run in args.runs:
        if not (run / "metrics.json").is_file():
            ap.error(f"{run}: no metrics.json (not a finished run)")
        cfg, source = run_config(run)
        cfgs.append(cfg)
        sources.append(source)
    ds = ex.load_data(cfgs[0], args.data or sources[0])
    prep = ex.prepare(ds)
    sel = ex.most_multimodal(prep, args.windows)
    x, y = prep.x[sel], prep.y[sel]
    idx, mask = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold)
    idx, mask = np.asarray(idx)[sel], np.asarray(mask)[sel]

    columns = []  # (label, (n, K, t_pred, D))
    for j, (run, cfg) in enumerate(zip(args.runs, cfgs)):
        params = ex.restore(cfg, prep, run)
        fns = ex.predictors(cfg, ds, params, args.k)
        name = args.samplers[j] if args.samplers else ex._main_predictor(cfg, fns)
        if name not in fns:
            ap.error(f"{run}: no sampler {name!r} at K={args.k}; it has {sorted(fns)}")
        pred = np.asarray(fns[name](jnp.asarray(x), jax.random.key(args.seed)))
        columns.append((f"{name} ({cfg.name})", pred))
        print(f"{run}: {name}, {pred.shape}", flush=True)

    parents = ds.skeleton.parents
    ncol = 1 + len(columns)
    fig, axes = plt.subplots(len(sel), ncol, figsize=(3.2 * ncol, 3.4 * len(sel)), squeeze=False)
    for r, w in enumerate(sel):
        xj = frames_to_joints(x[r])
        mm_ends = frames_to_joints(prep.y[idx[r][mask[r]], -1])
        up, across, _ = view_axes(np.concatenate([xj, frames_to_joints(y[r])]))
        panels = [(f"truth: {len(mm_ends)} MM futures", mm_ends, "k", None)]
        for label, pred in columns:
            ends = frames_to_joints(pred[r, :, -1])
            flat = pred[r].reshape(pred.shape[1], -1)
            d = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
            apd = d.sum() / max(len(flat) * (len(flat) - 1), 1)
            fde = np.linalg.norm(frames_to_joints(pred[r, :, -1]) - frames_to_joints(y[r, -1]), axis=-1).mean(-1).min()
            panels.append((f"{label}\nAPD {apd:.2f}  best FDE {fde:.3f}", ends, None, pred.shape[1]))
        for c, (title, ends, color, k) in enumerate(panels):
            ax = axes[r, c]
            draw_pose(ax, xj[-1], parents, across, up, color="0.6", lw=3)
            cols = [color] * len(ends) if color else plt.cm.viridis(np.linspace(0, 0.9, len(ends)))
            for e, col in zip(ends, cols):
                draw_pose(ax, e, parents, across, up, color=col, lw=1, alpha=0.35 if color else 0.5)
            ax.set_title(title if r == 0 or c == 0 else title.split("\n", 1)[-1], fontsize=8)
            if c == 0:
                ax.set_ylabel(f"window {int(w)}", fontsize=8)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"{ds.name}: end poses (frame +{ds.t_pred}) on the {len(sel)} most multimodal test windows, K = {args.k}", fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=80)
    plt.close(fig)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
