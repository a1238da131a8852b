"""Pictures of observed motion and predicted futures (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxmotion.formats.atomic import atomic_path  # noqa: E402


def frames_to_joints(frames: np.ndarray) -> np.ndarray:
    """Returns `(..., J, 3)` joints from root-relative root-dropped frame vectors `(..., (J-1)*3)`."""
    j = frames.reshape(frames.shape[:-1] + (-1, 3))
    root = np.zeros(j.shape[:-2] + (1, 3), j.dtype)
    return np.concatenate([root, j], axis=-2)


def view_axes(joints: np.ndarray) -> tuple[int, int, int]:
    """Returns `(up, across, depth)` axes: up is where a pose spans most (body height)."""
    span = np.ptp(joints.reshape(-1, joints.shape[-2], 3), axis=-2).mean(axis=0)
    up = int(np.argmax(span))
    rest = [a for a in range(3) if a != up]
    across = max(rest, key=lambda a: span[a])
    depth = [a for a in rest if a != across][0]
    return up, across, depth


def draw_pose(ax, pose, parents, h, v, dx=0.0, **kw):
    """Draws the bones of `pose (J, 3)` on `ax`, projected on the axes `h`, `v` and shifted by `dx`."""
    for j, p in enumerate(parents):
        if p >= 0:
            ax.plot([pose[p, h] + dx, pose[j, h] + dx], [pose[p, v], pose[j, v]], **kw)


def plot_futures(
    x: np.ndarray,
    preds: np.ndarray,
    gt: np.ndarray,
    parents: tuple[int, ...],
    path: str | Path,
    *,
    title: str = "",
    n_rows: int = 4,
    n_frames: int = 6,
    n_end: int = 12,
) -> Path:
    """Writes and returns a PNG of one window: end poses of the K futures, and a few futures over time.

    `x` `(t_his, D)`, `preds` `(K, t_pred, D)`, `gt` `(t_pred, D)` frame vectors. Row 1: the true
    end pose then the end poses of the first `n_end` samples side by side. Row 2: all K end poses
    overlaid in front and side view, and their pairwise distances. Below: the ground truth and
    `n_rows` samples as strips of `n_frames` poses over time, after the last observed pose (grey).
    """
    xj, pj, gj = frames_to_joints(x), frames_to_joints(preds), frames_to_joints(gt)
    up, across, depth = view_axes(np.concatenate([xj, gj]))
    k, t_pred = pj.shape[:2]
    colors = plt.cm.viridis(np.linspace(0, 0.9, k))
    step = 1.3 * max(np.ptp(xj[..., across]), np.ptp(xj[..., depth])) + 0.5
    fig = plt.figure(figsize=(15, 2.6 * (n_rows + 3)))
    gs = fig.add_gridspec(n_rows + 3, 3, height_ratios=[1.0, 1.4] + [1.0] * (n_rows + 1))

    def centred(pose):  # side by side: each end pose at its own horizontal centre (global data drifts)
        return pose - np.where(np.arange(3) == across, pose[:, across].mean(), 0.0)

    ax = fig.add_subplot(gs[0, :])
    draw_pose(ax, centred(gj[-1]), parents, across, up, color="k", lw=2)
    ax.text(0, np.max(gj[-1, :, up]) + 0.12, "truth", ha="center", fontsize=8)
    for i in range(min(n_end, k)):
        draw_pose(ax, centred(pj[i, -1]), parents, across, up, dx=(i + 1.3) * step, color=colors[i], lw=2)
        ax.text((i + 1.3) * step, np.max(gj[-1, :, up]) + 0.12, f"sample {i}", ha="center", fontsize=8)
    ax.set_title(f"end poses (frame +{t_pred}) of the true future and of {min(n_end, k)} of the {k} samples", fontsize=9)
    ax.set_aspect("equal")
    ax.axis("off")

    for col, (h, name) in enumerate([(across, "front"), (depth, "side")]):
        ax = fig.add_subplot(gs[1, col])
        draw_pose(ax, xj[-1], parents, h, up, color="0.6", lw=3)
        for i in range(k):
            draw_pose(ax, pj[i, -1], parents, h, up, color=colors[i], lw=1, alpha=0.5)
        draw_pose(ax, gj[-1], parents, h, up, color="k", lw=2, ls="--")
        ax.set_title(f"all {k} end poses ({name}); grey: last observed, dashed: truth", fontsize=9)
        ax.set_aspect("equal")
        ax.axis("off")
    ax = fig.add_subplot(gs[1, 2])
    flat = preds.reshape(k, -1)
    d = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
    im = ax.imshow(d, cmap="magma")
    fig.colorbar(im, ax=ax, fraction=0.046)
    ax.set_title("distance between samples (APD terms, m)", fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])

    times = np.linspace(0, t_pred - 1, n_frames).round().astype(int)
    strips = [("truth", gj, "k")] + [(f"sample {i}", pj[i], colors[i]) for i in range(min(n_rows, k))]
    for r, (name, seq, color) in enumerate(strips):
        ax = fig.add_subplot(gs[r + 2, :])
        draw_pose(ax, xj[-1], parents, across, up, dx=-step, color="0.6", lw=2)
        for c, t in enumerate(times):
            draw_pose(ax, seq[t], parents, across, up, dx=c * step, color=color, lw=2)
            if r == 0:
                ax.text(c * step, np.max(gj[..., up]) + 0.12, f"+{t + 1} fr", ha="center", fontsize=8)
        ax.text(-step, np.max(gj[..., up]) + 0.12, "last observed", ha="center", fontsize=8)
        ax.set_ylabel(name)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        for s in ax.spines.values():
            s.set_visible(False)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=80)
    plt.close(fig)
    return path
