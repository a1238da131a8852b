"""Predict from a marker file for a marker model (MOJO on markers): match labels, fill short gaps, canonicalise.

    jaxmotion predict runs/mojo_bandai_markers --input trial.c3d --k 5 --out futures/

The input is a C3D file (or an npz of `positions` with `names`; `predict_file.read_motion`): its
markers are matched by label to the model's (a `Subject:` prefix is dropped; an error lists the
missing and the extra markers). Gaps (unseen markers, NaN) of at most `MAX_GAP_S` seconds between
two seen samples are filled by linear interpolation, as mocap software's default gap filling does;
a longer gap, or one at the clip's start or end, inside the observed window is an error naming the
markers and input frames (without `--frame`, the latest window free of such gaps is used). Positions
are in metres (C3D POINT:UNITS), resampled to the model's frame rate by linear interpolation. The
observed window is put in MOJO's canonical frame of its first frame ([protocol §5][marker-canonicalisation]), computed
from the waist markers: X from the left to the right waist markers on the ground, Z the input's
up axis (the axis from the feet to the head markers), origin the waist markers' centre moved by
their mean attachment offset (`body.markersets.MARKER_SPECS`) onto the pelvis joint the training
frames were built on. Writes `futures.npz` (canonical frames as the model sees them, and the
markers back in the input's world, in metres) and `samples.gif`; no BVH: the model predicts marker
positions, not a skeleton's rotations.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from jaxmotion.body.markersets import MARKER_SPECS
from jaxmotion.data.windows import resample
from jaxmotion.errors import DataError, UsageError
from jaxmotion.formats.atomic import savez_atomic
from jaxmotion.tools.predictor import MotionPredictor

MAX_GAP_S = 0.1
_LEFT_WAIST, _RIGHT_WAIST = ("LFWT", "LBWT", "LASI", "LPSI"), ("RFWT", "RBWT", "RASI", "RPSI")
_UPPER = ("C7", "CLAV", "LFHD", "RFHD", "LBHD", "RBHD", "ARIEL")
_LOWER = ("LHEE", "RHEE", "LHEL", "RHEL", "LTOE", "RTOE", "LANK", "RANK")


def match_markers(path: Path, names: tuple[str, ...] | None, markers: list[str]) -> np.ndarray:
    """Returns the input index of each model marker, `(len(markers),)`, or raises `DataError` listing the missing and extra markers."""
    if names is None:
        raise DataError(path, f"markers are matched by label: add 'names' to the npz (the model's: {markers})")
    clean = [n.split(":")[-1].strip() for n in names]
    missing = [n for n in markers if n not in clean]
    extra = [n for n in clean if n not in markers]
    if missing:
        raise DataError(
            path, f"markers do not match the model's: missing {missing}; extra {extra} "
            f"(the model has {len(markers)} markers: {markers})"
        )
    return np.array([clean.index(n) for n in markers])


def fill_gaps(points: np.ndarray, max_gap: int) -> tuple[np.ndarray, int]:
    """Returns `(points, n_filled)`: runs of at most `max_gap` NaN frames between two seen frames, linearly interpolated per marker."""
    out = points.copy()
    seen = np.all(np.isfinite(points), axis=-1)  # (T, M)
    filled = 0
    t = np.arange(points.shape[0])
    for m in range(points.shape[1]):
        ok = np.nonzero(seen[:, m])[0]
        if len(ok) < 2:
            continue
        for a, b in zip(ok[:-1], ok[1:]):
            if 1 < b - a <= max_gap + 1:
                tt = t[a + 1 : b]
                w = ((tt - a) / (b - a))[:, None]
                out[a + 1 : b, m] = (1 - w) * points[a, m] + w * points[b, m]
                filled += int(b - a - 1)
    return out, filled


def up_vector(points: np.ndarray, names: tuple[str, ...]) -> tuple[np.ndarray, str]:
    """Returns `(unit signed axis, description)`: the axis from the foot markers to the head markers (Z when absent)."""
    up_i = [names.index(n) for n in _UPPER if n in names]
    lo_i = [names.index(n) for n in _LOWER if n in names]
    if not up_i or not lo_i:
        return np.array([0.0, 0.0, 1.0]), "z (no head and foot markers to tell)"
    d = np.nanmedian(np.nanmean(points[:, up_i], 1) - np.nanmean(points[:, lo_i], 1), axis=0)
    axis = int(np.argmax(np.abs(d)))
    v = np.zeros(3)
    v[axis] = np.sign(d[axis])
    return v, f"{'+' if v[axis] > 0 else '-'}{'xyz'[axis]} (from the foot to the head markers)"


def canonical_frame(frame: np.ndarray, names: tuple[str, ...], up: np.ndarray, path: Path) -> np.ndarray:
    """Returns `(4, 3)`: rows R (X hips left->right on the ground, Y = Z x X, Z up), then origin o ([protocol §5][marker-canonicalisation])."""
    left = [names.index(n) for n in _LEFT_WAIST if n in names]
    right = [names.index(n) for n in _RIGHT_WAIST if n in names]
    if not left or not right:
        raise DataError(path, f"the canonical frame needs left and right waist markers ({_LEFT_WAIST}, {_RIGHT_WAIST})")
    x = frame[right].mean(0) - frame[left].mean(0)
    x = x - (x @ up) * up
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    # The waist markers sit off the pelvis joint by their attachment (forward, left, up): undo the mean offset.
    used = [names[i] for i in left + right]
    fwd = np.mean([MARKER_SPECS[n].fwd for n in used if n in MARKER_SPECS] or [0.0])
    hgt = np.mean([MARKER_SPECS[n].up for n in used if n in MARKER_SPECS] or [0.0])
    origin = frame[left + right].mean(0) - fwd * y - hgt * up
    return np.stack([x, y, up, origin]).astype(np.float64)


def _runs(frames: np.ndarray) -> str:
    """Returns "3-7, 12" for sorted frame numbers."""
    out, start = [], None
    for i, f in enumerate(frames):
        if start is None:
            start = f
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            out.append(f"{start}" if start == f else f"{start}-{f}")
            start = None
    return ", ".join(out)


class MarkerWindow(NamedTuple):
    """The observed window of a marker clip in the model's canonical frame, its ground truth when the clip has it, and the way back."""

    x: np.ndarray  # (t_his, 3M) canonical frame of the window's first frame, the model's input
    gt: np.ndarray | None  # (t_pred, 3M) the frames after it, same frame, when the clip has them without gaps
    canon: np.ndarray  # (4, 3) rows R, then origin o: canonical q = R (p - o)
    observed: np.ndarray  # (t_his, M, 3) the observed markers in the input's world, metres
    end: int  # the window's last frame at the model's rate
    notes: list[str]


def marker_window(motion, lay: dict, frame: int | None = None) -> MarkerWindow:
    """Returns the observed window of `motion` (`predict_file.Motion`) for a marker model of layout `lay` (module docstring)."""
    markers = list(lay["joints"][1:])  # the layout's first point is the canonical origin, dropped from frames
    idx = match_markers(motion.path, motion.names, markers)
    notes = list(motion.notes)
    raw = motion.positions[:, idx].astype(np.float64)  # (n_in, M, 3) metres, NaN at gaps
    n_in = raw.shape[0]
    fps_in, fps = motion.fps, lay["fps"]
    if fps_in is None:
        notes.append(f"frame rate: not in the file, taken as the model's {fps:g} fps")
        fps_in = fps
    if frame is not None and not 0 <= frame < n_in:
        raise UsageError(f"--frame must be in [0, {n_in}) for {motion.path} ({n_in} frames), got {frame}")
    max_gap = int(round(MAX_GAP_S * fps_in))
    pos, filled = fill_gaps(raw, max_gap)
    gap_in = ~np.all(np.isfinite(pos), axis=-1)  # (n_in, M) what filling left, input frames
    if filled:
        notes.append(f"gaps: {filled} marker samples in gaps of at most {max_gap} frames ({MAX_GAP_S:g} s) linearly interpolated")
    ratio = fps / fps_in
    if abs(ratio - 1) > 0.01:
        pos = resample(pos, fps_in, fps, str(motion.path))
        notes.append(f"frame rate: resampled from {fps_in:g} to {fps:g} fps by linear interpolation ({n_in} -> {pos.shape[0]} frames); --frame counts input frames")
    else:
        ratio = 1.0
    n, t_his, t_pred = pos.shape[0], lay["t_his"], lay["t_pred"]
    gap = ~np.all(np.isfinite(pos), axis=-1)  # (n, M), model-rate frames
    # free[e]: the window of t_his frames ending at e has no gap.
    free = (np.convolve(gap.any(1).astype(int), np.ones(t_his, int))[:n] == 0) & (np.arange(n) >= t_his - 1)
    last = n - t_pred - 1 if n >= t_his + t_pred else n - 1
    if frame is not None:
        end = min(n - 1, int(round(frame * ratio)))
    else:
        ok = np.nonzero(free[: last + 1])[0]
        end = int(ok[-1]) if len(ok) else last
        if not len(ok):
            notes.append("window: no window of the clip is free of unfilled gaps")
        elif end != last:
            notes.append(f"window: the latest observed window without unfilled gaps ends at model-rate frame {end}")
    if end + 1 < t_his:
        raise DataError(
            motion.path, f"the observed window ending at frame {end} (model rate) has fewer than t_his = {t_his} frames "
            f"({t_his / fps:.2f} s at {fps:g} fps); the clip has {n} frames at that rate"
        )
    start = end + 1 - t_his
    window = slice(start, end + 1)
    if gap[window].any():
        a, b = int(np.floor(start / ratio)), min(n_in - 1, int(np.ceil(end / ratio)))
        where = [f"{markers[j]} (frames {_runs(a + np.nonzero(gap_in[a : b + 1, j])[0])})" for j in np.nonzero(gap_in[a : b + 1].any(0))[0]]
        none = " (no window of the clip is free of them)" if frame is None else ""
        raise DataError(
            motion.path, f"unseen markers in the observed window, input frames {a}-{b}{none}, in gaps longer than "
            f"{max_gap} frames ({MAX_GAP_S:g} s) or at the clip's ends: {'; '.join(where)}; choose another window with --frame"
        )
    up, up_note = up_vector(pos, tuple(markers))
    notes.append(f"up axis: {up_note}")
    canon = canonical_frame(pos[start], tuple(markers), up, motion.path)
    to_canon = lambda p: ((p - canon[3]) @ canon[:3].T).reshape(p.shape[0], -1).astype(np.float32)  # noqa: E731
    gt = None
    if end + t_pred < n:
        fut = pos[end + 1 : end + 1 + t_pred]
        if np.all(np.isfinite(fut)):
            gt = to_canon(fut)
        else:
            notes.append("ground truth: the frames after the window have unfilled gaps; the GIF shows none")
    return MarkerWindow(to_canon(pos[window]), gt, canon, pos[window], end, notes)


def predict_markers(
    model: MotionPredictor, motion, out: str | Path, *, frame: int | None = None, k: int | None = None,
    method: str | None = None, seed: int = 0, gif: bool = True,
) -> list[str]:
    """Writes the K futures of the marker window of `motion` (`predict_file.read_motion`) ending at input frame `frame` to `out`.

    Returns the lines to print. `predict_file.predict_file` reads the file and calls this for marker models.
    """
    lay = model.layout
    w = marker_window(motion, lay, frame)
    x, gt, canon, end, notes = w.x, w.gt, w.canon, w.end, w.notes
    fps, t_his, t_pred = lay["fps"], lay["t_his"], lay["t_pred"]
    markers = list(lay["joints"][1:])
    m = len(markers)
    k = model.default_k if k is None else k
    if method is None:
        method = model.main_method(k)
    futures = model.predict(x, k, jax.random.key(seed), method)  # (K, t_pred, 3M) canonical frame
    world = futures.reshape(k, t_pred, m, 3) @ canon[:3] + canon[3]  # R^T q + o, input world in metres
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    savez_atomic(
        out / "futures.npz", futures=futures, observed=x, ground_truth=gt if gt is not None else np.zeros((0,) + x.shape[1:]),
        markers=world.astype(np.float32), observed_markers=w.observed.astype(np.float32), canon=canon.astype(np.float32),
        names=np.array(markers), fps=fps, t_his=t_his, t_pred=t_pred, method=method, k=k, end_frame=end,
        input=str(motion.path), notes="\n".join(notes),
    )  # fmt: skip
    written = [out / "futures.npz"]
    if gif:
        from jaxmotion.pictures.animate import animate_futures

        written.append(animate_futures(
            x, futures, gt, tuple(lay["parents"]), out / "samples.gif", fps=fps,
            title=f"{motion.path.name}: frames {end + 1 - t_his}-{end} observed, {method}, K={k}",
        ))  # fmt: skip
    return [
        f"input: {motion.path} ({motion.positions.shape[0]} frames at {motion.fps or fps:g} fps, {len(motion.names)} markers)",
        f"model: {model.run_dir} ({model.manifest['dataset']['name']}, {model.config.method}; {m} markers, "
        f"{t_his} -> {t_pred} frames at {fps:g} fps)",
        *[f"note: {s}" for s in notes],
        f"observed: model-rate frames {end + 1 - t_his}..{end}" + ("" if gt is not None else " (no ground truth after it)"),
        f"predicted: K={k} futures with {method!r}; futures.npz holds them in the canonical frame of the window's first "
        "frame ('futures') and in the input's world in metres ('markers'); no BVH: a marker model predicts marker "
        "positions, not a skeleton's rotations",
        *[f"wrote {p}" for p in written],
    ]
