"""Animations of observed motion and predicted futures: a GIF through matplotlib's animation writers.

    animate_futures(x, preds, gt, parents, "samples.gif", fps=30)

One row of stick figures in front view: all K futures overlaid (the ground truth dashed), then the
ground truth and the first few futures side by side. Every panel plays the observed frames (grey),
then its future. Kept small (a few dozen frames, at least 1,200 pixels wide) so a report costs seconds.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.animation import FFMpegWriter, PillowWriter  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from jaxmotion.formats.atomic import atomic_path  # noqa: E402
from jaxmotion.pictures.viz import frames_to_joints, view_axes  # noqa: E402


def _segments(pose: np.ndarray, parents, h: int, v: int) -> np.ndarray:
    """Returns `(bones, 2, 2)` line segments of `pose (J, 3)` projected on axes `h`, `v`."""
    j = np.array([i for i, p in enumerate(parents) if p >= 0])
    p = np.asarray(parents)[j]
    return np.stack([pose[p][:, [h, v]], pose[j][:, [h, v]]], axis=1)


def animate_futures(
    x: np.ndarray,
    preds: np.ndarray,
    gt: np.ndarray | None,
    parents: tuple[int, ...],
    path: str | Path,
    *,
    fps: float = 30.0,
    title: str = "",
    n_side: int = 5,
    max_frames: int = 30,
    panel_inches: float = 1.7,
    dpi: int = 60,
    joints: bool = False,
    min_width: int = 1200,
) -> Path:
    """Writes and returns an animation (GIF, or MP4 when `path` ends in .mp4 and ffmpeg is there) of one window.

    `x` `(t_his, D)`, `preds` `(K, t_pred, D)`, `gt` `(t_pred, D)` or None: root-relative frame vectors
    (`joints=False`) or `(..., J, 3)` joint positions (`joints=True`). Frames are subsampled to at most
    `max_frames` and played at the recording's speed (`fps` of the data). The resolution is raised
    above `dpi` where needed to make the image at least `min_width` pixels wide.
    """
    path = Path(path)
    if joints:
        xj, pj = np.asarray(x, np.float64), np.asarray(preds, np.float64)
        gj = None if gt is None else np.asarray(gt, np.float64)
    else:
        xj, pj = frames_to_joints(np.asarray(x)), frames_to_joints(np.asarray(preds))
        gj = None if gt is None else frames_to_joints(np.asarray(gt))
    k, t_pred = pj.shape[:2]
    t_his = xj.shape[0]
    up, across, _ = view_axes(np.concatenate([xj, pj.reshape(-1, *pj.shape[2:])]))
    total = t_his + t_pred
    stride = max(1, int(np.ceil(total / max_frames)))
    times = np.arange(0, total, stride)
    if times[-1] != total - 1:
        times = np.append(times, total - 1)

    def seq(future):  # (total, J, 3): observed then this future
        return np.concatenate([xj, future])

    panels = [("all %d futures" % k, None)]
    if gj is not None:
        panels.append(("truth", seq(gj)))
    n = min(n_side, k)
    panels += [(f"future {i}", seq(pj[i])) for i in range(n)]
    every = np.concatenate([xj, pj.reshape(-1, *pj.shape[2:])] + ([] if gj is None else [gj]))
    lo = every[..., [across, up]].min(axis=(0, 1))
    hi = every[..., [across, up]].max(axis=(0, 1))
    half = 0.55 * (hi - lo).max()  # a square view around the motion, so panels are not squeezed
    lo, hi = (lo + hi) / 2 - half, (lo + hi) / 2 + half
    fig, axes = plt.subplots(1, len(panels), figsize=(panel_inches * len(panels), panel_inches * 1.25), squeeze=False)
    dpi = max(dpi, int(np.ceil(min_width / (panel_inches * len(panels)))))
    axes = axes[0]
    colors = plt.cm.viridis(np.linspace(0, 0.9, k))
    for ax, (name, _) in zip(axes, panels):
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(name, fontsize=7)
    # Panel 0: K futures overlaid (+ the truth dashed); others: one sequence each.
    over = [LineCollection([], colors=[colors[i]], linewidths=0.7, alpha=0.6) for i in range(k)]
    for c in over:
        axes[0].add_collection(c)
    truth0 = LineCollection([], colors="k", linewidths=1.2, linestyles="--")
    axes[0].add_collection(truth0)
    singles = []
    for i, (ax, (name, s)) in enumerate(zip(axes[1:], panels[1:])):
        c = LineCollection([], colors="k" if name == "truth" else [colors[i - (gj is not None)]], linewidths=1.5)
        ax.add_collection(c)
        singles.append((c, s, "k" if name == "truth" else colors[i - (gj is not None)]))
    label = fig.text(0.01, 0.01, "", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=7)
    fig.tight_layout(rect=(0, 0.04, 1, 0.93 if title else 1))
    # The layout is fixed from here on: without an engine the writer's savefig lays nothing out again (tight_layout
    # leaves a placeholder engine, for which every frame was drawn twice: once to lay out, once to grab).
    fig.set_layout_engine(None)

    def draw(t: int):
        observed = t < t_his
        for i, c in enumerate(over):
            c.set_segments(_segments(xj[t] if observed else pj[i, t - t_his], parents, across, up))
            c.set_color("0.5" if observed else colors[i])
        truth0.set_segments([] if observed or gj is None else _segments(gj[t - t_his], parents, across, up))
        for c, s, color in singles:
            c.set_segments(_segments(s[t], parents, across, up))
            c.set_color("0.5" if observed else color)
        label.set_text(f"observed {t + 1}/{t_his}" if observed else f"future +{t - t_his + 1}/{t_pred}")

    play_fps = max(1.0, fps / stride)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".mp4":
        if not FFMpegWriter.isAvailable():
            plt.close(fig)
            raise RuntimeError(f"{path}: MP4 needs ffmpeg on PATH; write a .gif instead")
        writer = FFMpegWriter(fps=play_fps)
    else:
        writer = PillowWriter(fps=play_fps)
    # The frames straight through the writer: each frame drawn once, as the writer grabs it. (FuncAnimation's
    # save draws every frame three times: after the update, once more for an interactive canvas, then to grab it.)
    with atomic_path(path) as tmp, writer.saving(fig, tmp, dpi):
        for t in times:
            draw(int(t))
            writer.grab_frame()
    plt.close(fig)
    return path
