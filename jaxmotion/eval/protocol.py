"""The protocol's averages over windows, and each published code base's deviation from them, as values.

[protocol §2][metrics] averages every metric over the test windows, MMADE / MMFDE over the windows with a
non-empty multimodal set. Some published evaluation code averages differently; each such deviation
is a `Deviation` value here (`DEVIATIONS`, chosen by `Config.mm_deviation`), off by default:

- `PROTOCOL` (None): the protocol.
- `DIVSAMP` ("divsamp", DivSamp's release): a window's set drops the other windows whose last pose
  is an exact duplicate of its own; windows with no other member are skipped in APD, ADE, FDE,
  MMADE and MMFDE, and those sums are still divided by the number of windows.
- `COMUSION` ("comusion", CoMusion's release): windows whose only member is themselves are dropped
  from MMADE / MMFDE.
- `GSPS` ("gsps", GSPS's release `eval.py`: `if gt_multi.shape[0] == 1: continue`): a test window
  whose set is itself alone enters no metric; the others are scored by the protocol. MM membership
  is symmetric, so no remaining window loses a member.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Literal, NamedTuple

import numpy as np
from beartype import beartype
from jaxtyping import ArrayLike, Float, Int, jaxtyped

from jaxmotion.eval.metrics import METRIC_NAMES, MMSets, multimodal_gt, window_metrics

_checked = jaxtyped(typechecker=beartype)
MMDeviation = Literal[None, "divsamp", "comusion"]


class WindowSets(NamedTuple):
    """The multimodal sets one evaluation scores with: members used, and how many each window has."""

    idx: np.ndarray  # (n, m) left-packed member indices into `futures`
    used: np.ndarray  # (n, m) the members that enter MMADE / MMFDE
    futures: ArrayLike  # (r, t_pred, D) the futures `idx` indexes
    n_members: np.ndarray  # (n,) set sizes as built (the window itself included in test-window sets)
    n_others: np.ndarray  # (n,) members other than the window itself that are used


@dataclasses.dataclass(frozen=True)
class Deviation:
    """The protocol ([protocol §2][metrics]). Subclasses reproduce published code; see the module docstring."""

    name: str | None = None
    needs_test_sets: bool = False  # only defined on the test windows' own sets
    skips_windows: bool = False  # windows whose set is themselves alone are left out of every metric

    def used(self, mask: np.ndarray, idx: np.ndarray, is_self: np.ndarray, poses: ArrayLike | None) -> np.ndarray:
        """Returns the `(N, M)` mask of the members that enter the MM terms (`mask`, `idx`, `is_self`: `(N, M)`)."""
        return mask

    def averages(self, per: dict[str, np.ndarray], n_others: np.ndarray) -> dict[str, float]:
        """Returns APD, ADE, FDE, ADE-m and FDE-m averaged over windows (`per`: name -> `(N,)`; `n_others`: `(N,)`)."""
        return {k: float(np.mean(per[k], dtype=np.float64)) for k in METRIC_NAMES if not k.startswith("MM")}

    def reduce(self, per_window: np.ndarray, n_members: np.ndarray, n_others: np.ndarray) -> tuple[float, int]:
        """Returns `(average, windows averaged)` of an MM metric: the mean over windows with a non-empty set."""
        keep = n_members > 0
        return float(per_window[keep].mean()) if keep.any() else float("nan"), int(keep.sum())


@dataclasses.dataclass(frozen=True)
class DivSampRelease(Deviation):
    """DivSamp's release: windows with no neighbour but themselves leave every metric's sum, not its count;
    exact-duplicate start poses leave the MM sets."""

    name: str | None = "divsamp"
    needs_test_sets: bool = True

    def used(self, mask, idx, is_self, poses):
        """Returns `mask` `(N, M)` without the members whose last pose equals the window's own (not itself)."""
        if poses is None:
            raise ValueError("mm_deviation='divsamp' needs the test windows' last poses (it drops exact duplicates)")
        poses = np.asarray(poses, np.float64)
        dup = np.all(poses[idx] == poses[:, None], axis=-1) & ~is_self
        return mask & ~dup

    def averages(self, per, n_others):
        """Returns the averages with APD, ADE and FDE summed over windows with a neighbour, divided by all `N`."""
        out = super().averages(per, n_others)
        keep, n = n_others > 0, n_others.shape[0]
        out.update({k: float(np.sum(per[k][keep], dtype=np.float64) / n) for k in ("APD", "ADE", "FDE")})
        return out

    def reduce(self, per_window, n_members, n_others):
        """Returns the sum over windows with a neighbour, divided by all `N`, and how many were summed."""
        keep = n_others > 0
        return float(per_window[keep].sum() / per_window.shape[0]), int(keep.sum())


@dataclasses.dataclass(frozen=True)
class CoMusionRelease(Deviation):
    """CoMusion's release: MMADE / MMFDE averaged over the windows with a neighbour other than themselves."""

    name: str | None = "comusion"

    def reduce(self, per_window, n_members, n_others):
        """Returns the mean over windows with a neighbour (NaN when none has one) and their number."""
        keep = n_others > 0
        return float(per_window[keep].mean()) if keep.any() else float("nan"), int(keep.sum())


@dataclasses.dataclass(frozen=True)
class GSPSRelease(Deviation):
    """GSPS's evaluation: windows whose MM set is themselves alone are left out of every metric."""

    name: str | None = "gsps"
    needs_test_sets: bool = True
    skips_windows: bool = True


PROTOCOL, DIVSAMP, COMUSION, GSPS = Deviation(), DivSampRelease(), CoMusionRelease(), GSPSRelease()
DEVIATIONS: dict[str | None, Deviation] = {d.name: d for d in (PROTOCOL, DIVSAMP, COMUSION, GSPS)}


def deviation(name: str | None) -> Deviation:
    """Returns the `Deviation` named `name` (`Config.mm_deviation`); a ValueError lists the names."""
    if name not in DEVIATIONS:
        raise ValueError(f"mm_deviation must be one of {tuple(DEVIATIONS)}, got {name!r}")
    return DEVIATIONS[name]


def multi_future_windows(last_poses: np.ndarray, thr: float) -> np.ndarray:
    """Returns the indices `(n,)` of the windows (last poses `(N, d)`) whose test-window MM set holds another window (what `GSPS` keeps)."""
    sets = multimodal_gt(last_poses, thr)
    idx, mask = np.asarray(sets.idx), np.asarray(sets.mask)
    sel = np.flatnonzero((mask & (idx != np.arange(len(idx))[:, None])).any(axis=1))
    if len(sel) == 0:
        raise ValueError(f"mm_deviation='gsps': none of the {len(idx)} test windows has another window within the MM threshold")
    return sel


def window_sets(sets: MMSets, gt: np.ndarray, futures: ArrayLike | None, dev: Deviation = PROTOCOL,
                poses: ArrayLike | None = None) -> WindowSets:
    """Returns the `WindowSets` of `sets` over `futures` `(R, t, d)` (None: the test windows' own futures `gt` `(N, t, d)`) under `dev`.

    `poses`: the windows' last observed poses, for the deviations that compare them (`DIVSAMP`).
    """
    fn = "evaluate_windows"
    mask = np.asarray(sets.mask, bool)
    if mask.ndim != 2:
        raise ValueError(f"{fn}: `mm.mask` must be (n, m), got shape {mask.shape}")
    if mask.shape[0] != gt.shape[0]:
        raise ValueError(f"{fn}: number of windows of `mm` ({mask.shape[0]}) does not match that of `gt` ({gt.shape[0]})")
    if np.shape(sets.idx) != mask.shape:
        raise ValueError(f"{fn}: shape of `mm.idx` ({np.shape(sets.idx)}) does not match that of `mm.mask` ({mask.shape})")
    idx = np.asarray(sets.idx)
    is_self = idx == np.arange(gt.shape[0])[:, None] if futures is None else np.zeros(mask.shape, bool)
    used = dev.used(mask, idx, is_self, poses)
    return WindowSets(idx, used, gt if futures is None else futures, mask.sum(axis=1), (used & ~is_self).sum(axis=1))


def averages(per: dict[str, np.ndarray], ws: WindowSets, dev: Deviation = PROTOCOL) -> dict[str, float]:
    """Returns the window averages of `per` (`window_metrics`' `(N,)` arrays) and the MM set statistics, under `dev`.

    Keys: `METRIC_NAMES`, `n_windows`; `MM_mean`, `MM_min`, `MM_max` (set sizes as built, i.e.
    including the window itself in test-window mode); `MM_only_self_frac` (fraction of windows with
    no MM future other than their own); `MM_n_averaged` (windows entering the MMADE/MMFDE average).
    """
    out = dev.averages(per, ws.n_others)
    n_used = ws.used.sum(axis=1)
    out["MMADE"], n_avg = dev.reduce(np.asarray(per["MMADE"], np.float64), n_used, ws.n_others)
    out["MMFDE"], _ = dev.reduce(np.asarray(per["MMFDE"], np.float64), n_used, ws.n_others)
    out.update(
        n_windows=float(ws.n_members.shape[0]),
        MM_mean=float(ws.n_members.mean()),
        MM_min=float(ws.n_members.min()),
        MM_max=float(ws.n_members.max()),
        MM_only_self_frac=float(np.mean(ws.n_others == 0)),
        MM_n_averaged=float(n_avg),
    )
    return out


@_checked
def reduce_mm(
    per_window: Float[ArrayLike, " n"],
    n_members: Int[ArrayLike, " n"],
    n_others: Int[ArrayLike, " n"],
    mm_deviation: MMDeviation = None,
) -> tuple[float, int]:
    """Returns `(average over windows, number of windows averaged)` of an MM metric ([protocol §2][metrics]).

    `per_window` must have been computed on the sets the deviation prescribes, `n_members` is the
    size of those sets and `n_others` the number of members other than the window itself; see
    `Deviation.reduce` and the module docstring for each `mm_deviation`.
    """
    return DEVIATIONS[mm_deviation].reduce(np.asarray(per_window, np.float64), np.asarray(n_members), np.asarray(n_others))


@_checked
def evaluate_windows(
    pred: Float[ArrayLike, "n k t d"] | Iterable[Float[ArrayLike, "c k t d"]],
    gt: Float[ArrayLike, "n t d"],
    mm: Float[ArrayLike, "n d"] | MMSets,
    *,
    thr: float | None = None,
    reference_last_poses: Float[ArrayLike, "r d"] | None = None,
    reference_futures: Float[ArrayLike, "r t d"] | None = None,
    mm_deviation: MMDeviation = None,
    chunk_size: int = 32,
    transfer_poses: Float[ArrayLike, "n d"] | None = None,
    transfer_parents: tuple[int, ...] | None = None,
) -> dict[str, float]:
    """Returns APD, ADE, FDE, MMADE, MMFDE, ADE-m, FDE-m averaged over windows, plus MM statistics ([protocol §2][metrics]).

        m = evaluate_windows(futures, gt, x[:, -1], thr=0.5)
        m["ADE"], m["MMADE"]   # metres

    Args:
        pred: the futures, `(N, K, t_pred, D)` metres, or an iterable of `(c, K, t_pred, D)` chunks in
            window order (a generator keeps memory flat).
        gt: each window's true future, `(N, t_pred, D)`.
        mm: the windows' flattened last observed poses `(N, D)` (the multimodal sets are then built with
            `multimodal_gt` at `thr`), or precomputed `MMSets`.
        thr: the multimodal threshold in metres (the dataset's, [protocol §4][datasets]); required with poses.
        reference_last_poses: `(R, D)` last observed poses of other windows (e.g. the training windows,
            MotionMap's tables) to build the sets from; needs `reference_futures`.
        reference_futures: `(R, t_pred, D)` futures of those windows: the multimodal ground truth instead of `gt`.
        mm_deviation: `None` (the protocol), or a published code's deviation (`DEVIATIONS`): "comusion"
            drops windows whose only member is themselves from MMADE / MMFDE; "divsamp" (`mm` must be the
            poses) drops exact-duplicate last poses from each set and skips windows with no other member
            while dividing by N (GSPS's, which skips windows, is `Config.mm_deviation` of a whole evaluation).
        chunk_size: windows per jitted call.
        transfer_poses: `(N, D)` poses whose bone lengths the multimodal futures are motion-transferred onto
            (MotionMap's evaluation; `mm` is then the `MMSets` of `motionmap_mm_sets`).
        transfer_parents: the skeleton's parent indices, with `transfer_poses`.

    Returns:
        `{name: float}`: "APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m" (metres; APD 0 when
            K = 1); "n_windows"; the multimodal sets' sizes "MM_mean", "MM_min", "MM_max" (as built, the
            window itself included with test-window sets); "MM_only_self_frac", the fraction of windows with
            no multimodal future but their own; "MM_n_averaged", the windows that enter MMADE / MMFDE.

    Raises:
        ValueError: shapes disagree, an input holds NaN / inf, `thr` is missing with poses, or a
            deviation is given inputs it cannot use.
    """
    fn = "evaluate_windows"
    gt = np.asarray(gt, np.float32)
    dev = DEVIATIONS[mm_deviation]
    if dev.needs_test_sets and (isinstance(mm, MMSets) or reference_futures is not None):
        raise ValueError(f"{fn}: mm_deviation='divsamp' needs `mm` as the test windows' last poses (it drops duplicates)")
    poses = None
    if isinstance(mm, MMSets):
        if reference_last_poses is not None:
            raise ValueError(f"{fn}: pass `reference_last_poses` only with last poses, not with `MMSets`")
        sets = mm
    else:
        if thr is None:
            raise ValueError(f"{fn}: `thr` is required when `mm` is the last observed poses")
        if reference_last_poses is not None and reference_futures is None:
            raise ValueError(f"{fn}: `reference_last_poses` needs `reference_futures`")
        sets = multimodal_gt(mm, thr, reference_last_poses=reference_last_poses)
        poses = mm
    ws = window_sets(sets, gt, reference_futures, dev, poses)
    per = window_metrics(pred, gt, ws.futures, ws.idx, ws.used, chunk_size=chunk_size, transfer_poses=transfer_poses,
                         transfer_parents=transfer_parents)
    return averages(per, ws, dev)
