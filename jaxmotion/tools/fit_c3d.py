"""Fit the skeleton body to a C3D recording, gaps included, and draw markers and the fitted skeleton.

    python -m jaxmotion.tools.fit_c3d ../shared/data/vicon-c3d/squat.c3d --out squat_fit.png

Steps: read the labelled markers (`formats.c3d`); build a skeleton body with the file's markers (the
`vicon53` layout, on the built-in 21-joint skeleton or on `--skeleton FILE.bvh`); calibrate bone
lengths and marker offsets on `--calib-frames` frames spread over the recording (`fit.calibrate`);
fit every `--stride`-th frame in one `lax.scan`, each frame warm-started from the previous one
(`fit.fit_sequence`); print the median and 95th percentile of the per-marker residual over the
markers seen, and write a PNG. `--json` writes the numbers.

A command-line script beside `cli.py`: it uses `jaxmotion.body` and `jaxmotion.formats`, and nothing
in the library imports it.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.body.fit import calibrate, fit_sequence
from jaxmotion.body.markersets import MARKER_SPECS
from jaxmotion.body.skeleton import SkeletonBody, skeleton_body_from_bvh, toy_skeleton
from jaxmotion.data.plausible import check_positions
from jaxmotion.formats.atomic import atomic_path, write_text_atomic
from jaxmotion.formats.bvh import read_bvh
from jaxmotion.formats.c3d import read_c3d


def fit_c3d(path, *, skeleton: str | None = None, stride: int = 1, calib_frames: int = 32, rounds: int = 4) -> dict:
    """Returns a dict with the body, fits, observed points/mask, timings and residual statistics (mm)."""
    rec = read_c3d(path)
    check_positions(path, rec.points, "marker positions", gaps=True, units=f"POINT:UNITS says {rec.units}")
    names = tuple(n for n in rec.labels if n in MARKER_SPECS)
    if len(names) < 8:
        raise ValueError(f"{path}: only {len(names)} labels have an attachment in MARKER_SPECS: {names}")
    if skeleton is None:
        body: SkeletonBody = toy_skeleton(names)
    else:
        body = skeleton_body_from_bvh(read_bvh(skeleton), names)
    pts, msk = rec.select(names)
    pts, msk = pts[::stride], msk[::stride]
    seen = msk.mean(axis=1)
    good = np.flatnonzero(seen >= 0.9)
    good = good if len(good) >= calib_frames else np.argsort(-seen)[:calib_frames]
    idx = np.sort(good[np.linspace(0, len(good) - 1, calib_frames).round().astype(int)])

    t0 = time.perf_counter()
    cal = jax.jit(lambda t, m: calibrate(body, t, m, rounds=rounds))(jnp.asarray(pts[idx]), jnp.asarray(msk[idx]))
    jax.block_until_ready(cal)
    t_cal = time.perf_counter() - t0
    first = int(np.argmax(seen >= 0.5))
    init = jax.tree.map(lambda a: a[np.argmin(np.abs(idx - first))], cal.fits.params)
    t0 = time.perf_counter()
    seq = jax.jit(lambda t, m, p: fit_sequence(cal.body, t, p, m))
    # Fit forwards from the first well-observed frame, and backwards from it for the frames before.
    fwd = seq(jnp.asarray(pts[first:]), jnp.asarray(msk[first:]), init)
    jax.block_until_ready(fwd)
    fits = fwd
    if first > 0:
        bwd = seq(jnp.asarray(pts[:first][::-1]), jnp.asarray(msk[:first][::-1]), init)
        fits = jax.tree.map(lambda b, f: jnp.concatenate([b[::-1], f]), bwd, fwd)
    t_fit = time.perf_counter() - t0
    res = np.asarray(fits.residual)[msk] * 1000.0
    return {
        "file": str(path), "frames": int(len(pts)), "markers": len(names), "seen_fraction": float(msk.mean()),
        "median_mm": float(np.median(res)), "p95_mm": float(np.percentile(res, 95)), "mean_mm": float(res.mean()),
        "calibration_s": round(t_cal, 2), "fit_s": round(t_fit, 2),
        "body": cal.body, "fits": fits, "points": pts, "mask": msk,
    }  # fmt: skip


def plot_fit(out: dict, png: str | Path, n_frames: int = 4) -> Path:
    """Writes a PNG of observed markers (dots), fitted markers (crosses) and the fitted skeleton."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    body, fits, pts, msk = out["body"], out["fits"], out["points"], out["mask"]
    frames = np.linspace(0, len(pts) - 1, n_frames + 2).round().astype(int)[1:-1]
    joints = np.asarray(jax.vmap(body.joints)(jax.tree.map(lambda a: a[frames], fits.params)))
    span = np.ptp(joints.reshape(-1, 3), axis=0)
    up = int(np.argmax(np.ptp(joints, axis=1).mean(0)))
    h = [a for a in range(3) if a != up][int(np.argmax([span[a] for a in range(3) if a != up]))]
    fig, axes = plt.subplots(1, n_frames, figsize=(3.2 * n_frames, 4.6), squeeze=False)
    for ax, f, j in zip(axes[0], frames, joints):
        m = np.asarray(fits.markers[f])
        for k, p in enumerate(body.parents):
            if p >= 0:
                ax.plot([j[p, h], j[k, h]], [j[p, up], j[k, up]], "-", color="tab:blue", lw=2)
        o = pts[f][msk[f]]
        ax.plot(o[:, h], o[:, up], "o", ms=4, mfc="none", color="k", label="observed")
        ax.plot(m[:, h], m[:, up], "x", ms=4, color="tab:red", label="fitted")
        gap = ~msk[f]
        if gap.any():
            ax.plot(m[gap, h], m[gap, up], "s", ms=5, mfc="none", color="tab:orange", label="gap (predicted)")
        r = np.asarray(fits.residual[f])[msk[f]] * 1000
        ax.set_title(f"frame {f}: median {np.median(r):.1f} mm", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle(
        f"{Path(out['file']).name}: {out['markers']} markers, skeleton body fit; all frames median "
        f"{out['median_mm']:.1f} mm, p95 {out['p95_mm']:.1f} mm",
        fontsize=10,
    )
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
    return png


def main(argv=None) -> None:
    """Runs `python -m jaxmotion.tools.fit_c3d FILE`: fits, prints the statistics as JSON and writes the picture."""
    ap = argparse.ArgumentParser(prog="python -m jaxmotion.tools.fit_c3d", description=__doc__.split("\n\n")[0])
    ap.add_argument("file", help="a .c3d file with labelled markers")
    ap.add_argument("--out", default=None, help="PNG to write (default: FILE stem + _fit.png in the current folder)")
    ap.add_argument("--skeleton", default=None, help="a BVH file whose skeleton to use (default: built-in 21 joints)")
    ap.add_argument("--stride", type=int, default=1, help="fit every n-th frame")
    ap.add_argument("--calib-frames", type=int, default=32)
    ap.add_argument("--json", default=None, help="also write the numbers to this JSON file")
    args = ap.parse_args(argv)
    out = fit_c3d(args.file, skeleton=args.skeleton, stride=args.stride, calib_frames=args.calib_frames)
    png = plot_fit(out, args.out or f"{Path(args.file).stem}_fit.png")
    stats = {k: v for k, v in out.items() if k not in ("body", "fits", "points", "mask")}
    print(json.dumps(stats))
    print(f"wrote {png}")
    if args.json:
        write_text_atomic(args.json, json.dumps(stats, indent=1))


if __name__ == "__main__":
    main()
