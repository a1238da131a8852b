"""Plain containers shared by every loader: a skeleton, a sequence, a dataset split."""

from __future__ import annotations

import dataclasses

import numpy as np


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
    """One recording: global joint positions in metres, `(T, J, 3)`."""

    positions: np.ndarray
    fps: float
    subject: str
    action: str
    name: str = ""


@dataclasses.dataclass
class MotionDataset:
    """A dataset under the evaluation protocol (PROTOCOL sec. 3).

    `skeleton` describes the kept joints (root first); a frame vector drops the root, so
    `dim == (skeleton.num_joints - 1) * 3`.
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

    @property
    def t_total(self) -> int:
        return self.t_his + self.t_pred

    @property
    def dim(self) -> int:
        return (self.skeleton.num_joints - 1) * 3
