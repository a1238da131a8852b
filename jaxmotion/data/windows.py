"""Windows of `t_his` observed + `t_pred` future frames ([protocol §1][representation] and [protocol §4][datasets])."""

from __future__ import annotations

import numpy as np

from jaxmotion.data.types import Sequence
from jaxmotion.errors import DataError

# Resampling's bounds, checked before anything is allocated: a clip whose frame rate is absurd (a corrupt
# header, a resource bomb) asks for millions of frames. An hour at 120 fps is 432,000 frames.
MAX_RESAMPLED_FRAMES = 1_000_000
MAX_RESAMPLE_BYTES = 1 << 30  # of float64 output: 1 GiB


def to_frames(positions: np.ndarray, root: int = 0) -> np.ndarray:
    """Returns `(T, (J-1)*3)` root-relative frame vectors with the root joint dropped.

    `positions` is `(T, J, 3)`; every joint is expressed relative to `root` in the same frame.
    """
    positions = np.asarray(positions)
    if positions.ndim != 3 or positions.shape[-1] != 3:
        raise ValueError(f"to_frames: positions must be (T, J, 3), got shape {positions.shape}")
    if not np.all(np.isfinite(positions)):
        raise ValueError("to_frames: positions contain NaN or inf")
    rel = positions - positions[:, root : root + 1]
    rel = np.delete(rel, root, axis=1)
    return rel.reshape(rel.shape[0], -1).astype(np.float32)


def test_starts(num_frames: int, t_total: int, step: int) -> np.ndarray:
    """Returns the start frames of test windows in one sequence.

    DLow's `iter_generator(step)` uses `range(0, T - t_total, step)`: the last possible start
    (`T - t_total`) is excluded. We keep that exactly so window counts match published code.
    """
    return np.arange(0, max(num_frames - t_total, 0), step, dtype=np.int64)


def test_windows(frames: list[np.ndarray], t_his: int, t_pred: int, step: int | None = None):
    """Returns `(windows (N, t_his+t_pred, D), seq_index (N,), start (N,))`.

    Windows start every `step` frames (default `t_his`, [protocol §4][datasets]) of each sequence in
    `frames` (a list of `(T, D)` arrays).
    """
    step = t_his if step is None else step
    t_total = t_his + t_pred
    out, seq_idx, starts = [], [], []
    for i, f in enumerate(frames):
        s = test_starts(f.shape[0], t_total, step)
        if len(s):
            idx = s[:, None] + np.arange(t_total)[None, :]
            out.append(f[idx])
            seq_idx.append(np.full(len(s), i))
            starts.append(s)
    if not out:
        raise ValueError(f"test_windows: no sequence is longer than t_his + t_pred = {t_total} frames")
    return np.concatenate(out), np.concatenate(seq_idx), np.concatenate(starts)


def canonicalise_windows(windows: np.ndarray, canon: np.ndarray) -> np.ndarray:
    """Returns `windows (N, T, M*3)` of global points expressed in their canonical frames `canon (N, 4, 3)`.

    `canon[i]` is the frame of window i's first frame (`Sequence.canon` at its start): `R (p - o)`.
    """
    n, t, d = windows.shape
    p = windows.reshape(n, t, d // 3, 3) - canon[:, None, None, 3]
    return np.einsum("ntmj,nij->ntmi", p, canon[:, :3]).reshape(n, t, d).astype(np.float32)


class TrainSampler:
    """Draws training windows at random start frames ([protocol §4][datasets]).

    `weighting="windows"` (default): a sequence is chosen with probability proportional to its
    number of valid starts, so every valid window is equally likely. `weighting="sequences"`: DLow's
    release (`sample_iter_action`): a sequence uniformly, then a start in `[0, T - t_total)`, so a
    sequence of exactly `t_total` frames is never drawn. `weighting="subjects"` (needs `subjects`, one
    name per sequence): the releases' `sample()` (DLow, GSPS, DivSamp, HumanMAC): a subject uniformly,
    then one of its sequences of at least `t_total` frames uniformly, then a start in `[0, T - t_total)`,
    drawn again when the sequence has exactly `t_total` frames. On HumanEva-I this draws a third of the
    windows from Train/S3, whose 11 takes hold 4% of the valid starts. Uses a numpy Generator seeded explicitly.
    With `canon` (one `(T, 4, 3)` array per sequence, marker data) each window is expressed in the
    canonical frame of its first frame.
    """

    def __init__(
        self, frames: list[np.ndarray], t_total: int, canon: list[np.ndarray] | None = None, weighting: str = "windows",
        subjects: list[str] | None = None,
    ):
        if weighting not in SAMPLER_WEIGHTINGS:
            raise ValueError(f"TrainSampler: weighting must be one of {SAMPLER_WEIGHTINGS}, got {weighting!r}")
        if weighting == "subjects" and (subjects is None or len(subjects) != len(frames)):
            raise ValueError(f"TrainSampler: weighting 'subjects' needs one subject name per sequence ({len(frames)})")
        # DLow's release draws starts in [0, T - t_total): it needs T > t_total.
        min_len = t_total if weighting == "windows" else t_total + 1
        weight = np.ones(len(frames))
        if weighting == "subjects":
            # A subject, then one of its sequences the loaders keep (>= t_total frames); a draw of one
            # with exactly t_total frames is drawn again, i.e. the others' weights are renormalised.
            kept = [sub for f, sub in zip(frames, subjects) if f.shape[0] >= t_total]
            weight = np.array([1.0 / kept.count(sub) if f.shape[0] >= t_total else 0.0 for f, sub in zip(frames, subjects)])
        weight = [w for f, w in zip(frames, weight) if f.shape[0] >= min_len]
        if canon is not None:
            if len(canon) != len(frames):
                raise ValueError(f"TrainSampler: {len(canon)} canonical-frame arrays for {len(frames)} sequences")
            canon = [c for f, c in zip(frames, canon) if f.shape[0] >= min_len]
        self.canon = canon
        self.frames = [f for f in frames if f.shape[0] >= min_len]
        if not self.frames:
            raise ValueError(f"TrainSampler: no sequence has at least {min_len} frames (t_total = {t_total}, {weighting!r})")
        self.t_total, self.weighting = t_total, weighting
        counts = np.array([f.shape[0] - min_len + 1 for f in self.frames], dtype=np.float64)
        if weighting == "windows":
            self.p = counts / counts.sum()
        else:
            self.p = np.asarray(weight) / np.sum(weight)
        self.num_windows = int(counts.sum())

    def sample(self, rng: np.random.Generator, batch_size: int) -> np.ndarray:
        """Returns `(batch_size, t_total, D)` float32 windows."""
        seqs = rng.choice(len(self.frames), size=batch_size, p=self.p)
        out = np.empty((batch_size, self.t_total, self.frames[0].shape[1]), np.float32)
        canon = np.empty((batch_size, 4, 3)) if self.canon is not None else None
        for b, s in enumerate(seqs):
            f = self.frames[s]
            start = rng.integers(0, f.shape[0] - self.t_total + (1 if self.weighting == "windows" else 0))
            out[b] = f[start : start + self.t_total]
            if canon is not None:
                canon[b] = self.canon[s][start]
        return out if canon is None else canonicalise_windows(out, canon)


SAMPLER_WEIGHTINGS = ("windows", "sequences", "subjects")


def sequence_frames(seqs: list[Sequence], root: int = 0) -> list[np.ndarray]:
    """Returns the frame vectors `(T_i, d)` of each sequence (see `to_frames`)."""
    return [to_frames(s.positions, root) for s in seqs]


def split_frames(ds, split: str) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
    """Returns `(frames, canon)` of `ds.train` or `ds.test` (`split`): root-relative frame vectors
    for joint datasets (canon None); for marker datasets (`ds.info["frames"] == "global"`) the
    flattened global points and each sequence's `canon`, to canonicalise windows at their start."""
    seqs = getattr(ds, split)
    if ds.info.get("frames") != "global":
        return sequence_frames(seqs), None
    frames, canon = [], []
    for s in seqs:
        p = np.asarray(s.positions, np.float32)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"{ds.name}: sequence {s.name!r} has NaN or inf positions")
        if s.canon is None or s.canon.shape != (p.shape[0], 4, 3):
            raise ValueError(f"{ds.name}: marker sequence {s.name!r} needs `canon` of shape ({p.shape[0]}, 4, 3)")
        frames.append(p.reshape(p.shape[0], -1))
        canon.append(s.canon)
    return frames, canon


# These are library functions, not tests: keep pytest from collecting them where they are imported.
test_starts.__test__ = False
test_windows.__test__ = False


def resample(positions: np.ndarray, fps_in: float, fps_out: float, path: str = "positions") -> np.ndarray:
    """Returns `(T', ...)` positions at `fps_out` by linear interpolation in time over the same span (frame 0 kept).

    Raises `DataError` naming `path` when a rate is not a finite positive number or the result would pass
    `MAX_RESAMPLED_FRAMES` or `MAX_RESAMPLE_BYTES`.
    """
    for name, fps in (("input", fps_in), ("output", fps_out)):
        if not (np.isfinite(fps) and fps > 0):
            raise DataError(path, f"{name} frame rate must be a finite number > 0, got {fps}")
    n_in = positions.shape[0]
    n_out = int(np.floor(max(n_in - 1, 0) / fps_in * fps_out + 1e-9)) + 1
    size = n_out * int(np.prod(positions.shape[1:])) * 8
    if n_out > MAX_RESAMPLED_FRAMES or size > MAX_RESAMPLE_BYTES:
        raise DataError(
            path, f"resampling {n_in} frames from {fps_in:g} to {fps_out:g} fps gives {n_out} frames ({size / 2**30:.2f} GiB); "
            f"the limits are {MAX_RESAMPLED_FRAMES} frames and {MAX_RESAMPLE_BYTES / 2**30:g} GiB (is the file's frame rate right?)"
        )
    t_in = np.arange(positions.shape[0]) / fps_in
    t_out = np.arange(0.0, t_in[-1] + 1e-9, 1.0 / fps_out)
    flat = positions.reshape(positions.shape[0], -1)
    out = np.stack([np.interp(t_out, t_in, flat[:, c]) for c in range(flat.shape[1])], axis=1)
    return out.reshape((len(t_out),) + positions.shape[1:])
