"""Plain containers shared by every loader (a skeleton, a sequence, a dataset split), and their finite-values check."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from jaxmotion.errors import DataError


@dataclasses.dataclass(frozen=True)
class Skeleton:
    """Joint names and parent indices (-1 for the root); joint 0 is the root."""

    names: tuple[str, ...]
    parents: tuple[int, ...]

    def __post_init__(self):
        if len(self.names) != len(self.parents):
            raise ValueError(f"Skeleton: {len(self.names)} names but {len(self.parents)} parents")

    @property
    def num_joints(self) -> int:
        return len(self.names)


@dataclasses.dataclass
class Sequence:
    """One recording: global joint (or marker) positions in metres, `(T, J, 3)`.

    `canon` (marker datasets, [protocol §5][marker-canonicalisation]) holds per frame t the canonical frame that a window
    starting at t is expressed in: rows 0-2 the rotation R, row 3 the origin o (`p' = R (p - o)`).
    """

    positions: np.ndarray
    fps: float
    subject: str
    action: str
    name: str = ""
    canon: np.ndarray | None = None  # (T, 4, 3)


@dataclasses.dataclass
class MotionDataset:
    """A dataset under the evaluation protocol ([protocol §4][datasets]).

    `skeleton` describes the kept joints (root first); a frame vector drops the root, so
    `dim == (skeleton.num_joints - 1) * 3`. Marker datasets (`info["frames"] == "global"`) keep
    global positions, canonicalised per window (`Sequence.canon`): their skeleton is a point
    `origin` (the canonical origin, dropped like a root) followed by the markers, whose parents
    only draw a stick figure.
    """

    name: str
    skeleton: Skeleton
    fps: float
    t_his: int
    t_pred: int
    mm_threshold: float
    train: list[Sequence]
    test: list[Sequence]
    info: dict = dataclasses.field(default_factory=dict)
    # A dataset that knows every test window's possible futures (the synthetic data) gives a
    # function `dataset -> (modes (N, P, t_pred, D), probs (P,), true_mode (N,), boundary (N,))`
    # in test-window order; evaluation then reports mode recall.
    known_modes: Callable[["MotionDataset"], Any] | None = None

    @property
    def t_total(self) -> int:
        return self.t_his + self.t_pred

    @property
    def dim(self) -> int:
        return (self.skeleton.num_joints - 1) * 3


def check_finite(path: str | os.PathLike, positions: np.ndarray, what: str = "positions") -> None:
    """Raises `DataError` naming `path`, the frame and the joint of the first NaN/inf in `positions` (F, J, 3)."""
    bad = ~np.isfinite(positions)
    if bad.any():
        f, j = (int(v) for v in np.argwhere(bad)[0][:2])
        n = int(bad.any(axis=-1).sum())
        raise DataError(path, f"{what}: non-finite value {positions[f, j][bad[f, j]][0]} at frame {f}, joint {j} ({n} non-finite joint positions in all)")
