"""Where MMADE / MMFDE's multimodal ground truth comes from ([protocol §2][metrics] and its options), as values.

A reference builds, for the test windows of a `Prepared`, an `MMGroundTruth`: the sets of
futures each window is compared with, the futures those sets index, and (MotionMap's) the
skeleton each member is motion-transferred onto. `Config.mm_ground_truth` names one of
`REFERENCES` (None: the method's own, `Method.reference_futures`):

- "test" (`TestWindows`, the protocol): the test windows whose last observed pose is within the
  dataset's threshold of this window's.
- "train" (`TrainWindows`): the same over the training windows (every `t_his` frames of every
  training sequence), a pool of pseudo ground truth some published code compares against.
- "motionmap-test" / "motionmap-train" (`MotionMapSets`, MotionMap appendix A): the descriptor is
  the last three observed frames; a candidate is a member when its descriptor, motion-transferred
  onto this window's skeleton (its last observed frame), is within the threshold of this window's,
  and the members' futures are motion-transferred onto that skeleton before MMADE / MMFDE.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxmotion.data.prepare import Prepared
from jaxmotion.data.windows import test_windows
from jaxmotion.eval.metrics import MMSets, motionmap_mm_sets, multimodal_gt

# MotionMap's descriptor: the last three observed frames (paper appendix A; protocol §2 (docs/pages/protocol.md#metrics) option).
MOTIONMAP_DESCRIPTOR_FRAMES = 3


class MMGroundTruth(NamedTuple):
    """The multimodal ground truth of an evaluation: sets, the futures they index and how they are compared."""

    source: str  # the reference's name (`REFERENCES`), recorded as each record's `mm_source`
    sets: MMSets
    futures: np.ndarray | None  # the futures `sets` index; None: the test windows' own ground truth
    transfer_poses: np.ndarray | None  # MotionMap: each test window's last observed pose (its skeleton)
    transfer_parents: tuple[int, ...] | None  # MotionMap: the skeleton's parents (root first)

    def rows(self, sel: np.ndarray) -> MMGroundTruth:
        """Returns the ground truth of the test windows `sel` (indices `(n,)`; their sets still index every future)."""
        sets = MMSets(np.asarray(self.sets.idx)[sel], np.asarray(self.sets.mask)[sel])
        poses = None if self.transfer_poses is None else self.transfer_poses[sel]
        return self._replace(sets=sets, transfer_poses=poses)

    def transfer(self) -> dict:
        """Returns the motion-transfer keywords of `metrics.window_metrics` (empty without transfer)."""
        if self.transfer_parents is None:
            return {}
        return dict(transfer_poses=self.transfer_poses, transfer_parents=self.transfer_parents)


def _training_windows(prep: Prepared, name: str) -> np.ndarray:
    if prep.train_frames is None:
        raise ValueError(f"MM ground truth {name!r}: training-window reference futures need uncanonicalised frames")
    ds = prep.dataset
    return test_windows(prep.train_frames, ds.t_his, ds.t_pred)[0]


@dataclasses.dataclass(frozen=True)
class TestWindows:
    """The protocol's sets: test windows with a similar last observed pose ([protocol §2][metrics])."""

    name: str = "test"

    def build(self, prep: Prepared, cache_dir: str | Path | None = None) -> MMGroundTruth:
        """Returns the ground truth of `prep`'s test windows: the test windows' sets over their own futures."""
        return MMGroundTruth(self.name, multimodal_gt(prep.x[:, -1], prep.dataset.mm_threshold), None, None, None)


@dataclasses.dataclass(frozen=True)
class TrainWindows:
    """Training windows with a similar last observed pose, and their futures."""

    name: str = "train"

    def build(self, prep: Prepared, cache_dir: str | Path | None = None) -> MMGroundTruth:
        """Returns the ground truth of `prep`'s test windows: the training windows' sets and futures."""
        ds, ref = prep.dataset, _training_windows(prep, self.name)
        sets = multimodal_gt(prep.x[:, -1], ds.mm_threshold, reference_last_poses=ref[:, ds.t_his - 1])
        return MMGroundTruth(self.name, sets, ref[:, ds.t_his :], None, None)


@dataclasses.dataclass(frozen=True)
class MotionMapSets:
    """MotionMap's sets over the test windows (`pool="test"`) or the training windows (`pool="train"`)."""

    pool: str = "train"

    @property
    def name(self) -> str:
        return f"motionmap-{self.pool}"

    def build(self, prep: Prepared, cache_dir: str | Path | None = None) -> MMGroundTruth:
        """Returns the ground truth of `prep`'s test windows: MotionMap's sets, with the poses their futures are motion-transferred onto."""
        ds = prep.dataset
        ref = _training_windows(prep, self.name) if self.pool == "train" else None
        if prep.train_frames is None:
            raise ValueError(f"MM ground truth {self.name!r}: motion transfer needs joint frames, not marker frames")
        parents = tuple(int(q) for q in ds.skeleton.parents)
        f = min(MOTIONMAP_DESCRIPTOR_FRAMES, ds.t_his)
        ref_desc = None if ref is None else ref[:, ds.t_his - f : ds.t_his]
        sets = motionmap_mm_sets(prep.x[:, -f:], ds.mm_threshold, parents, reference_desc=ref_desc, cache_dir=cache_dir)
        futures = None if ref is None else ref[:, ds.t_his :]
        return MMGroundTruth(self.name, sets, futures, np.asarray(prep.x[:, -1], np.float32), parents)


REFERENCES = {r.name: r for r in (TestWindows(), TrainWindows(), MotionMapSets("test"), MotionMapSets("train"))}


def reference(name: str):
    """Returns the reference named `name` (`Config.mm_ground_truth`, `Method.reference_futures`)."""
    if name not in REFERENCES:
        raise ValueError(f"MM ground truth: source must be one of {tuple(REFERENCES)}, got {name!r}")
    return REFERENCES[name]
