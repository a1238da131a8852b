"""Protocol windows of a dataset: the training sampler and the test windows every method is scored on.

`prepare(ds)` returns a `Prepared`: the frame vectors for training (a `TrainSampler`) and the
protocol's test windows ([protocol §4][datasets]: test stride t_his, random training starts), with where
each test window comes from. Training, evaluation and the pictures all read this one value.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxmotion.data.types import MotionDataset
from jaxmotion.data.windows import SAMPLER_WEIGHTINGS, TrainSampler, canonicalise_windows, split_frames, test_windows
from jaxmotion.errors import DataError

__all__ = ["Prepared", "prepare", "check_lengths"]


@dataclasses.dataclass
class Prepared:
    """Frame vectors for training and the protocol test windows of one dataset."""

    dataset: MotionDataset
    sampler: TrainSampler | None  # None for a test-only preparation (`prepare(test_only=True)`)
    windows: np.ndarray  # (N, t_total, D)
    seq_index: np.ndarray
    starts: np.ndarray
    keep: np.ndarray  # indices of these windows among all protocol test windows
    train_frames: list[np.ndarray] | None = None  # the training split's frame vectors (uncanonicalised)

    @property
    def x(self) -> np.ndarray:
        return self.windows[:, : self.dataset.t_his]

    @property
    def y(self) -> np.ndarray:
        return self.windows[:, self.dataset.t_his :]


def prepare(ds: MotionDataset, max_test_windows: int | None = None, train_sampler: str = "windows", test_only: bool = False) -> Prepared:
    """Returns train sampler and test windows ([protocol §4][datasets]: test stride t_his, random train starts).

    `train_sampler` weights the training windows (`TrainSampler`): "windows" (each equally likely)
    or "sequences" (a sequence uniformly, then a start) or "subjects" (the releases' `sample()`: a
    subject, then one of its sequences, then a start). `test_only`: no training
    windows are needed (the sampler is None), e.g. to evaluate a trained model on a new folder.

    Marker datasets' windows are canonicalised at their first frame ([protocol §5][marker-canonicalisation]).
    """
    train, train_canon = split_frames(ds, "train")
    test, test_canon = split_frames(ds, "test")
    check_lengths(ds, train, test, train_sampler, test_only)
    subjects = [sq.subject for sq in ds.train] if train_sampler == "subjects" else None
    sampler = None if test_only else TrainSampler(train, ds.t_total, train_canon, weighting=train_sampler, subjects=subjects)
    windows, seq_index, starts = test_windows(test, ds.t_his, ds.t_pred)
    if test_canon is not None:
        windows = canonicalise_windows(windows, np.stack([test_canon[i][s] for i, s in zip(seq_index, starts)]))
    keep = np.arange(len(windows))
    if max_test_windows is not None and len(windows) > max_test_windows:
        # Evenly spaced, so a quick evaluation still covers every test sequence.
        keep = np.linspace(0, len(windows) - 1, max_test_windows).round().astype(int)
        windows, seq_index, starts = windows[keep], seq_index[keep], starts[keep]
    return Prepared(ds, sampler, windows, seq_index, starts, keep, train if train_canon is None else None)


def check_lengths(
    ds: MotionDataset, train: list[np.ndarray], test: list[np.ndarray], train_sampler: str = "windows", test_only: bool = False
) -> None:
    """Raises `DataError` saying how many sequences there are, how long the longest is and what the protocol needs,
    when no training window (unless `test_only`) or no test window fits in the `(T_i, d)` sequences ([protocol §4][datasets]: test windows need T > t_total)."""
    if train_sampler not in SAMPLER_WEIGHTINGS:
        return  # TrainSampler names the choices
    need = ds.t_total + (1 if train_sampler in ("sequences", "subjects") else 0)
    if (test_only or any(len(f) >= need for f in train)) and any(len(f) > ds.t_total for f in test):
        return
    longest = lambda fs: max((len(f) for f in fs), default=0)  # noqa: E731
    which = "training" if not test_only and not any(len(f) >= need for f in train) else "test"
    hint = ""
    if "split" in ds.info:
        hint = f" Split: {ds.info['split']}. Choose other test files with --test-files, or train at a lower frame rate (data_options={{'fps': 30}}) or with shorter windows (data_options t_his / t_pred)."
    raise DataError(
        ds.info.get("source", ds.name),
        f"no {which} window fits: {len(ds.train)} training sequences (longest {longest(train)} frames) and "
        f"{len(ds.test)} test sequences (longest {longest(test)} frames); the protocol needs "
        f"t_his + t_pred = {ds.t_his} + {ds.t_pred} = {ds.t_total} frames at {ds.fps:g} fps "
        f"({'a test sequence longer than that' if which == 'test' else f'a training sequence of at least {need}'}).{hint}",
    )
