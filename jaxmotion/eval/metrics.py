"""Diversity and accuracy metrics of stochastic motion prediction ([protocol §2][metrics], DLow definitions).

Shapes: predictions `pred (N, K, t_pred, D)`, ground truth `gt (N, t_pred, D)`; every distance is
Euclidean over the whole D-vector of a frame (or over the whole `t_pred * D` vector for APD).

Every metric is first computed per window (functions returning `(N,)` arrays, all jittable), then
averaged over windows by `evaluate_windows`, which streams over window chunks so that
`N * K * t_pred * D` predictions never have to exist at once, and which is the only place where the
known deviations of published code (`mm_deviation="divsamp" | "comusion"`) can be switched on.

Argument checks. Shapes are checked by the jaxtyping annotations of the public entry points, which
are decorated with `jaxtyped(typechecker=beartype)` so that the check runs for every user, not only
under the test suite's import hook: a wrong number of dimensions, or axes that disagree between
arguments (N, K, t_pred, D, M), raise `jaxtyping.TypeCheckError` (a `TypeError`) naming the
argument and the axis sizes bound so far. Under `jit` the check costs nothing at run time (it runs
while tracing). What an annotation cannot say stays a hand-written `ValueError`: NaN / inf
inputs, `idx` entries outside the futures, non-positive thresholds, and the chunks of an iterable
`pred`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator
from functools import partial
from pathlib import Path
from typing import Literal, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from beartype import beartype
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, jaxtyped

from jaxmotion.body.bones import bone_lengths, bone_vectors, frame_parents, motion_transfer  # noqa: F401 (public here too)
from jaxmotion.formats.atomic import savez_atomic
from jaxmotion.losses import gram

METRIC_NAMES = ("APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m")


class MMSets(NamedTuple):
    """Multimodal ground-truth sets, left-packed: `idx[i, :count_i]` are valid where `mask` is True."""

    idx: Int[Array, "n m"]
    mask: Bool[Array, "n m"]


# --------------------------------------------------------------------------------------------
# Boundary checks. Shapes: the annotations, checked by `_checked` on every public entry point.
# Values: below, on concrete inputs only, so the public functions still trace under jit.

_checked = jaxtyped(typechecker=beartype)


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _check_finite(fn: str, name: str, x):
    if not _is_traced(x) and not np.all(np.isfinite(np.asarray(x))):
        raise ValueError(f"{fn}: `{name}` contains NaN or inf")


def _check_same(fn: str, what: str, a_name: str, a: object, b_name: str, b: object):
    if a != b:
        raise ValueError(f"{fn}: {what} of `{a_name}` ({a}) does not match that of `{b_name}` ({b})")


def _check_idx(fn: str, idx, mask, n_futures: int):
    if not _is_traced(idx) and not _is_traced(mask):
        i, m = np.asarray(idx), np.asarray(mask, bool)
        if m.any() and (i[m].min() < 0 or i[m].max() >= n_futures):
            raise ValueError(f"{fn}: `idx` has entries outside [0, {n_futures}) where `mask` is True")


def _check_pred_gt(fn: str, pred, gt):
    _check_finite(fn, "pred", pred)
    _check_finite(fn, "gt", gt)
    return jnp.asarray(pred, jnp.float32), jnp.asarray(gt, jnp.float32)


def _check_mm(fn: str, pred, futures, idx, mask):
    _check_finite(fn, "pred", pred)
    _check_finite(fn, "futures", futures)
    _check_idx(fn, idx, mask, futures.shape[0])
    return (
        jnp.asarray(pred, jnp.float32),
        jnp.asarray(futures, jnp.float32),
        jnp.asarray(idx, jnp.int32),
        jnp.asarray(mask, bool),
    )


# --------------------------------------------------------------------------------------------
# Per-window metrics.


def _frame_dists(pred: Float[Array, "n k t d"], gt: Float[Array, "n t d"]) -> Float[Array, "n k t"]:
    return jnp.sqrt(jnp.sum((pred - gt[:, None]) ** 2, axis=-1))


@jax.jit
def _ade_terms(pred: Float[Array, "n k t d"], gt: Float[Array, "n t d"]) -> Float[Array, "n k"]:
    return jnp.mean(_frame_dists(pred, gt), axis=-1)


@jax.jit
def _fde_terms(pred: Float[Array, "n k t d"], gt: Float[Array, "n t d"]) -> Float[Array, "n k"]:
    return _frame_dists(pred[:, :, -1:], gt[:, -1:])[..., 0]


@partial(jax.jit, static_argnames="how")
def _reduce_k(terms: Float[Array, "n k"], how: Literal["min", "median"]) -> Float[Array, " n"]:
    return jnp.min(terms, axis=-1) if how == "min" else jnp.median(terms, axis=-1)


def _safe_sqrt(d2: Float[Array, "..."]) -> Float[Array, "..."]:
    # The inner `where` keeps the gradient finite (zero) where a distance is 0, e.g. duplicate samples.
    pos = d2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, d2, 1.0)), 0.0)


# Samples per block of APD's product: beyond one block only the blocks on and above the diagonal
# are computed, the others being their transposes (K = 1000: 36 products of 125 x 125, not 64).
APD_BLOCK = 128


def _apd_window(x: Float[Array, "k f"]) -> Float[Array, ""]:
    # ||a - b||^2 = |a|^2 + |b|^2 - 2 a.b: a K x K matrix product. Distances do not change under
    # translation, so the samples are first taken relative to sample 0: the norms are then of the
    # order of the distances (little cancellation), and samples equal to sample 0 are exactly
    # zero. The norms come from the product's own diagonal, so that two identical samples give
    # |a|^2 + |a|^2 - 2 |a|^2 = 0 rather than a rounding residue.
    k = x.shape[0]
    x = x - x[:1]
    nb = -(-k // APD_BLOCK)
    size = -(-k // nb)
    xb = jnp.pad(x, ((0, nb * size - k), (0, 0))).reshape(nb, size, -1)
    valid = (jnp.arange(nb * size) < k).reshape(nb, size)
    diag = [gram(xb[i], xb[i]) for i in range(nb)]
    sq = [jnp.diagonal(g) for g in diag]
    total = jnp.float32(0)
    for i in range(nb):
        for j in range(i, nb):
            g = diag[i] if i == j else gram(xb[i], xb[j])
            d = _safe_sqrt(jnp.maximum(sq[i][:, None] + sq[j][None, :] - 2.0 * g, 0.0))
            keep = valid[i][:, None] & valid[j][None, :]
            if i == j:
                keep &= ~jnp.eye(size, dtype=bool)
            # A block above the diagonal stands for its transpose too: each unordered pair counts twice,
            # like the pairs inside a diagonal block, so the mean over i != j is the mean over i < j.
            total += (1.0 if i == j else 2.0) * jnp.sum(jnp.where(keep, d, 0.0))
    return total / (k * (k - 1))


@jax.jit
def _apd(pred: Float[Array, "n k t d"]) -> Float[Array, " n"]:
    n, k = pred.shape[:2]
    if k == 1:
        return jnp.zeros((n,), jnp.float32)
    # One window at a time: a plain matrix product on cache-sized operands runs several times
    # faster on CPU than XLA's batched product over windows.
    return lax.map(_apd_window, pred.reshape(n, k, -1))


@_checked
def apd(pred: Float[ArrayLike, "n k t d"]) -> Float[Array, " n"]:
    """Returns per-window APD `mean_{i<j} ||vec(Yhat_i) - vec(Yhat_j)||_2` ([protocol §2][metrics]); 0 when K = 1."""
    _check_finite("apd", "pred", pred)
    return _apd(jnp.asarray(pred, jnp.float32))


@_checked
def ade(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"]) -> Float[Array, " n"]:
    """Returns per-window ADE `min_k (1/t_pred) sum_t ||Yhat_{k,t} - Y_t||_2` ([protocol §2][metrics])."""
    pred, gt = _check_pred_gt("ade", pred, gt)
    return _reduce_k(_ade_terms(pred, gt), "min")


@_checked
def fde(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"]) -> Float[Array, " n"]:
    """Returns per-window FDE `min_k ||Yhat_{k,T} - Y_T||_2` ([protocol §2][metrics])."""
    pred, gt = _check_pred_gt("fde", pred, gt)
    return _reduce_k(_fde_terms(pred, gt), "min")


@_checked
def ade_median(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"]) -> Float[Array, " n"]:
    """Returns per-window ADE-m: the ADE term's median over k instead of its min ([protocol §2][metrics]).

    For even K the median is the mean of the two middle values (numpy's convention).
    """
    pred, gt = _check_pred_gt("ade_median", pred, gt)
    return _reduce_k(_ade_terms(pred, gt), "median")


@_checked
def fde_median(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"]) -> Float[Array, " n"]:
    """Returns per-window FDE-m: the FDE term's median over k instead of its min ([protocol §2][metrics])."""
    pred, gt = _check_pred_gt("fde_median", pred, gt)
    return _reduce_k(_fde_terms(pred, gt), "median")


@jax.jit
def _ffe_terms(pred: Float[Array, "n k t d"], gt: Float[Array, "n t d"]) -> Float[Array, "n k"]:
    return _frame_dists(pred[:, :, :1], gt[:, :1])[..., 0]


@_checked
def first_frame_error(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"]) -> Float[Array, " n"]:
    """Returns per-window FFE `min_k ||Yhat_{k,1} - Y_1||_2`: FDE at the first predicted frame.

    A future that does not continue the observed motion (a jump onto other proportions or another pose)
    shows here before it shows in ADE; zero-velocity's FFE is the motion of one frame.
    """
    pred, gt = _check_pred_gt("first_frame_error", pred, gt)
    return _reduce_k(_ffe_terms(pred, gt), "min")


# --------------------------------------------------------------------------------------------
# Multimodal ground truth.


@_checked
def multimodal_gt(
    last_poses: Float[ArrayLike, "n d"],
    thr: float,
    *,
    exclude_self: bool = False,
    reference_last_poses: Float[ArrayLike, "r d"] | None = None,
    max_chunk_elems: int = 2_000_000,
) -> MMSets:
    """Returns left-packed `MMSets(idx (N, M), mask (N, M))` with `MM(i) = {j : ||c_i - c_j||_2 < thr}` ([protocol §2][metrics]).

    `M` is the largest set size. By default the candidates `j` are the test windows themselves and
    `MM(i)` includes `i` (`exclude_self=True` drops it). With `reference_last_poses` (e.g. the last
    observed poses of training windows, for MotionMap comparisons) the candidates are those
    reference windows instead, `idx` indexes the matching reference futures, and a window's own
    ground truth is not a member; such a window may have an empty set.

    The set sizes are data dependent, so this runs on the host, in float64 and with exact
    differences like DLow's `scipy.spatial.distance.pdist`, so that pairs near `thr` fall on the
    same side as in published code. Rows are processed in chunks of about `max_chunk_elems`
    numbers, so memory stays small for N of many thousands.
    """
    fn = "multimodal_gt"
    _check_finite(fn, "last_poses", last_poses)
    c = np.asarray(last_poses, np.float64)
    if not np.isfinite(thr) or thr <= 0:
        raise ValueError(f"{fn}: `thr` must be a positive finite distance, got {thr}")
    if reference_last_poses is None:
        ref = c
    else:
        if exclude_self:
            raise ValueError(f"{fn}: `exclude_self` has no meaning with `reference_last_poses`")
        _check_finite(fn, "reference_last_poses", reference_last_poses)
        ref = np.asarray(reference_last_poses, np.float64)
    n, n_ref = c.shape[0], ref.shape[0]
    rows_per_chunk = max(1, max_chunk_elems // max(1, n_ref * c.shape[1]))
    rows, cols = [], []
    for s in range(0, n, rows_per_chunk):
        diff = c[s : s + rows_per_chunk, None, :] - ref[None]
        near = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff)) < thr
        if reference_last_poses is None:
            # Decide self-membership by index so that `exclude_self` removes exactly window i,
            # never another window that happens to share its pose.
            r = np.arange(near.shape[0])
            near[r, s + r] = not exclude_self
        i, j = np.nonzero(near)
        rows.append(i + s)
        cols.append(j)
    idx, mask = _left_packed(rows, cols, n)
    return MMSets(jnp.asarray(idx), jnp.asarray(mask))


def _left_packed(rows: list[np.ndarray], cols: list[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray]:
    # The (row, member) pairs of `np.nonzero` chunks as left-packed `(idx, mask)`, (n, max members).
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    counts = np.bincount(rows, minlength=n)
    m = max(1, int(counts.max(initial=0)))
    # np.nonzero returns row-major order, so each row's members are contiguous.
    pos = np.arange(rows.size) - np.repeat(np.cumsum(counts) - counts, counts)
    idx, mask = np.zeros((n, m), np.int32), np.zeros((n, m), bool)
    idx[rows, pos], mask[rows, pos] = cols, True
    return idx, mask


# --------------------------------------------------------------------------------------------
# MotionMap's multimodal ground truth (protocol §2 (docs/pages/protocol.md#metrics) option; MotionMap appendix A): candidates
# are motion-transferred onto the window's skeleton before they are compared, and so are their futures.


def _pair_near_fn(parents: tuple[int, ...]):
    @jax.jit
    def near(desc_q: Float[Array, "p f d"], desc_ref: Float[Array, "p f d"], thr: Float[Array, ""]) -> Bool[Array, " p"]:
        # The definition, pair by pair: reference descriptor p onto query p's skeleton (its last observed frame).
        moved = motion_transfer(desc_ref, desc_q[:, -1:], parents)  # (p, f, d)
        diff = moved.reshape(moved.shape[0], -1) - desc_q.reshape(desc_q.shape[0], -1)
        return jnp.sqrt(jnp.sum(diff**2, axis=-1)) < thr

    return near


def _transfer_distance_features(
    desc_q: np.ndarray, desc_ref: np.ndarray, parents: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Returns float64 `(fq, fr, xx)` with `fq[i] @ fr[j] + xx[i]` = the squared distance between query i and
    reference j moved onto i's skeleton, `||vec(transfer(ref_j -> skeleton of q_i)) - vec(q_i)||^2`.

    A transferred joint is the sum of its chain's bones, each the reference's unit direction `u` times the
    query's length `l`: `pos_k = sum_b A[k, b] l_b u_b`. Expanding the square, the reference enters through
    `u` and the Gram matrix of its directions, the query through its lengths, its own positions and
    `C = A^T A`, so every pair's distance is one product of two feature rows.
    """
    fp = frame_parents(parents)
    n_b = len(fp)
    chain = np.zeros((n_b, n_b))  # chain[k, b] = 1 where bone b is on the path from the root to joint k
    for k in range(n_b):
        b = k
        while b >= 0:
            chain[k, b], b = 1.0, fp[b]
    q = np.asarray(bone_vectors(desc_q, parents), np.float64)  # (n, f, b, 3)
    n, f = q.shape[:2]
    length = np.linalg.norm(q[:, -1], axis=-1)  # (n, b): the query's skeleton, its last frame
    x = desc_q.astype(np.float64).reshape(n, f, n_b, 3)
    quad = chain.T @ chain * length[:, :, None] * length[:, None, :]  # (n, b, b)
    lin = -2.0 * length[:, None, :, None] * np.einsum("kb,nfkc->nfbc", chain, x)  # (n, f, b, 3)
    r = np.asarray(bone_vectors(desc_ref, parents), np.float64)
    u = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-12)  # (r, f, b, 3)
    gram_u = np.einsum("rfbc,rfec->rbe", u, u)  # (r, b, b), summed over frames
    fq = np.concatenate([quad.reshape(n, -1), lin.reshape(n, -1)], axis=1)
    fr = np.concatenate([gram_u.reshape(len(r), -1), u.reshape(len(r), -1)], axis=1)
    return fq, fr, np.sum(x**2, axis=(1, 2, 3))


# Pairs whose float64 distance is within this fraction of (thr + the largest coordinate) of the threshold
# are decided by the definition itself (`_pair_near_fn`, float32), so the sets are exactly the definition's.
MM_BAND = 1e-4
MM_PAIR_BATCH = 16_384


def motionmap_mm_sets(
    desc: Float[np.ndarray, "n f d"],
    thr: float,
    parents: tuple[int, ...],
    *,
    reference_desc: Float[np.ndarray, "r f d"] | None = None,
    max_chunk_elems: int = 4_000_000,
    cache_dir: str | Path | None = None,
) -> MMSets:
    """Returns left-packed `MMSets` of MotionMap's multimodal ground truth (appendix A; [protocol §2][metrics] option).

    `desc[i]` is window i's descriptor (its last three observed frames). Candidate j is a member of
    MM(i) when `||vec(transfer(desc_j -> skeleton of i)) - vec(desc_i)|| < thr`, the skeleton of i
    being its last observed frame. Candidates are the windows themselves (i is always a member of
    its own set) or `reference_desc` (e.g. training windows, MotionMap Tables 1-2). Every distance is
    one product of two float64 feature rows (`_transfer_distance_features`), chunked over query windows
    (about `max_chunk_elems` distances per chunk); pairs within `MM_BAND` of the threshold are decided
    by the definition itself, pair by pair in float32, so the sets are the definition's (33,243 windows
    against each other: 28 s on a 2-core CPU, where transferring every pair took 16 min). With
    `cache_dir` the sets are stored in a file keyed by the data, the threshold and the skeleton.
    """
    desc = np.asarray(desc, np.float32)
    if not np.all(np.isfinite(desc)):
        raise ValueError("motionmap_mm_sets: `desc` contains NaN or inf")
    if not np.isfinite(thr) or thr <= 0:
        raise ValueError(f"motionmap_mm_sets: `thr` must be a positive distance, got {thr}")
    ref = desc if reference_desc is None else np.asarray(reference_desc, np.float32)
    cache = None
    if cache_dir is not None:
        h = hashlib.sha1(desc.tobytes())
        h.update(ref.tobytes() if reference_desc is not None else b"self")
        h.update(repr((float(thr), tuple(parents), desc.shape, ref.shape)).encode())
        cache = Path(cache_dir) / f"motionmap_mm_{h.hexdigest()[:20]}.npz"
        if cache.exists():
            z = np.load(cache)
            return MMSets(jnp.asarray(z["idx"]), jnp.asarray(z["mask"]))
    pair_near = _pair_near_fn(tuple(parents))
    fq, fr, xx = _transfer_distance_features(desc, ref, tuple(parents))
    n, r = desc.shape[0], ref.shape[0]
    band = MM_BAND * (thr + float(max(np.abs(desc).max(), np.abs(ref).max())))
    c = int(max(1, min(n, max_chunk_elems // max(1, r))))
    rows, cols, unsure = [], [], []
    for s in range(0, n, c):
        dist = np.sqrt(np.maximum(fq[s : s + c] @ fr.T + xx[s : s + c, None], 0.0))
        close = np.abs(dist - thr) <= band
        near = (dist < thr) & ~close
        if reference_desc is None:  # a window is a member of its own set
            k = np.arange(dist.shape[0])
            near[k, s + k], close[k, s + k] = True, False
        i, j = np.nonzero(near)
        rows.append(i + s)
        cols.append(j)
        i, j = np.nonzero(close)
        unsure.append(np.stack([i + s, j], axis=1))
    pairs = np.concatenate(unsure)
    for s in range(0, len(pairs), MM_PAIR_BATCH):
        pq = pairs[s : s + MM_PAIR_BATCH]
        pad = min(MM_PAIR_BATCH, 1 << max(8, (len(pq) - 1).bit_length())) - len(pq)  # few compiled shapes
        iq, ir = np.pad(pq[:, 0], (0, pad)), np.pad(pq[:, 1], (0, pad))
        ok = np.asarray(pair_near(jnp.asarray(desc[iq]), jnp.asarray(ref[ir]), jnp.asarray(thr, jnp.float32)))[: len(pq)]
        rows.append(pq[ok, 0])
        cols.append(pq[ok, 1])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    order = np.lexsort((cols, rows))  # each row's members contiguous and in order, as `_left_packed` wants
    rows, cols = [rows[order]], [cols[order]]
    idx, mask = _left_packed(rows, cols, n)
    if cache is not None:  # whole or not at all: another process may be reading or writing the same sets
        savez_atomic(cache, idx=idx, mask=mask)
    return MMSets(jnp.asarray(idx), jnp.asarray(mask))


# Elements of the (t_pred, K, members) distance block `_mm_window` holds at once (1 MB: cache-sized).
MM_BLOCK_ELEMS = 256_000


def _mm_window(
    pred: Float[Array, "k t d"], idx: Int[Array, " m"], mask: Bool[Array, " m"], futures: Float[Array, "r t d"],
    target: Float[Array, " d"] | None = None, parents: tuple[int, ...] | None = None,
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    # Per frame, ||p - f||^2 = |p|^2 + |f|^2 - 2 p.f: a block of set members costs one batched
    # matrix product (t_pred products of K x D by D x members) instead of K * members explicit
    # differences. Both sides are first taken relative to the window's first member (distances
    # do not change), so their norms are of the order of the distances and that member's own
    # terms are exact. The loop over member blocks stops at the window's last valid member, so
    # cost follows its own set size rather than the global M. With `parents`, every member's future
    # is first motion-transferred onto the skeleton of `target` (MotionMap's evaluation).
    def members(ib):
        f = futures[ib]
        return f if parents is None else motion_transfer(f, target, parents)

    k, t, _ = pred.shape
    m = idx.shape[0]
    block = min(m, max(8, MM_BLOCK_ELEMS // (k * t)))
    pad = -m % block
    idx, mask = jnp.pad(idx, (0, pad)), jnp.pad(mask, (0, pad))
    centre = members(idx[:1])[0]  # (t, d)
    p = jnp.swapaxes(pred - centre, 0, 1)  # (t, K, d)
    pp = jnp.sum(p * p, axis=-1)[:, :, None]  # (t, K, 1)
    p = -2.0 * p  # exact (a power of two): the product below is then -2 p.f
    last = jnp.max(jnp.where(mask, jnp.arange(1, m + pad + 1), 0))

    def body(j, carry):
        s_ade, s_fde = carry
        ib = lax.dynamic_slice_in_dim(idx, j * block, block)
        mb = lax.dynamic_slice_in_dim(mask, j * block, block)
        f = jnp.swapaxes(members(ib) - centre, 0, 1)  # (t, block, d)
        ff = jnp.sum(f * f, axis=-1)[:, None, :]  # (t, 1, block)
        # A plain sqrt: the loop's data-dependent length rules out reverse-mode gradients anyway.
        d = jnp.sqrt(jnp.maximum(pp + ff + gram(p, f), 0.0))  # (t, K, block)
        s_ade += jnp.sum(jnp.where(mb, jnp.min(jnp.sum(d, axis=0), axis=0), 0.0)) / t
        s_fde += jnp.sum(jnp.where(mb, jnp.min(d[-1], axis=0), 0.0))
        return s_ade, s_fde

    s_ade, s_fde = lax.fori_loop(0, (last + block - 1) // block, body, (jnp.float32(0), jnp.float32(0)))
    count = jnp.sum(mask)
    # 0 / 0 = NaN for an empty set on purpose: the aggregation decides what an empty set means.
    return s_ade / count, s_fde / count


def _mm_batch(
    pred: Float[Array, "b k t d"],
    idx: Int[Array, "b m"],
    mask: Bool[Array, "b m"],
    futures: Float[Array, "r t d"],
    targets: Float[Array, "b d"] | None = None,
    parents: tuple[int, ...] | None = None,
) -> tuple[Float[Array, " b"], Float[Array, " b"]]:
    # One window at a time (cache-sized operands, each its own number of member blocks).
    if parents is None:
        return lax.map(lambda a: _mm_window(*a, futures), (pred, idx, mask))
    return lax.map(lambda a: _mm_window(*a[:3], futures, a[3], parents), (pred, idx, mask, targets))


@partial(jax.jit, static_argnames=("batch_size", "parents"))
def _mm_errors(pred, futures, idx, mask, batch_size, targets=None, parents=None):
    n = pred.shape[0]
    b = max(1, min(batch_size, n))
    pad = -n % b

    def batched(x):
        x = jnp.concatenate([x, jnp.zeros((pad,) + x.shape[1:], x.dtype)])
        return x.reshape((-1, b) + x.shape[1:])

    if parents is None:
        xs = (batched(pred), batched(idx), batched(mask))
        mm_ade, mm_fde = lax.map(lambda a: _mm_batch(*a, futures), xs)
    else:
        xs = (batched(pred), batched(idx), batched(mask), batched(targets))
        mm_ade, mm_fde = lax.map(lambda a: _mm_batch(*a[:3], futures, a[3], parents), xs)
    return mm_ade.reshape(-1)[:n], mm_fde.reshape(-1)[:n]


@_checked
def mm_errors(
    pred: Float[ArrayLike, "n k t d"],
    futures: Float[ArrayLike, "r t d"],
    idx: Int[ArrayLike, "n m"],
    mask: Bool[ArrayLike, "n m"],
    *,
    batch_size: int = 16,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Returns per-window `(MMADE, MMFDE)`: mean over `m in MM(i)` of `min_k` ADE/FDE term vs `futures[m]` ([protocol §2][metrics]).

    `idx`/`mask` come from `multimodal_gt`; `futures` are the futures it indexes (the test
    ground truth, or the reference futures). Windows with an empty set give NaN. Windows are
    processed `batch_size` at a time and their set members in blocks, each block's distances one
    batched matrix product, so memory is bounded (`MM_BLOCK_ELEMS`) whatever M is.
    """
    pred, futures, idx, mask = _check_mm("mm_errors", pred, futures, idx, mask)
    return _mm_errors(pred, futures, idx, mask, batch_size)


@_checked
def mm_errors_transferred(
    pred: Float[ArrayLike, "n k t d"],
    last_pose: Float[ArrayLike, "n d"],
    futures: Float[ArrayLike, "r t d"],
    idx: Int[ArrayLike, "n m"],
    mask: Bool[ArrayLike, "n m"],
    parents: tuple[int, ...],
    *,
    batch_size: int = 16,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Returns per-window `(MMADE, MMFDE)` with each MM future motion-transferred onto the window's skeleton first.

    MotionMap's evaluation ([protocol §2][metrics], MotionMap option): `futures[idx[i, m]]` is moved onto
    the skeleton of `last_pose[i]` before the min-over-K ADE / FDE term. NaN for an empty set. The
    same blocked kernel as `mm_errors`.
    """
    pred, futures, idx, mask = _check_mm("mm_errors_transferred", pred, futures, idx, mask)
    parents = tuple(int(q) for q in parents)
    frame_parents(parents)
    return _mm_errors(pred, futures, idx, mask, batch_size, jnp.asarray(last_pose, jnp.float32), parents)


@_checked
def mmade(
    pred: Float[ArrayLike, "n k t d"],
    futures: Float[ArrayLike, "r t d"],
    idx: Int[ArrayLike, "n m"],
    mask: Bool[ArrayLike, "n m"],
    *,
    batch_size: int = 16,
) -> Float[Array, " n"]:
    """Returns per-window MMADE `mean_{m in MM(i)} min_k ADE-term(Yhat_k, Y_m)` ([protocol §2][metrics]); see `mm_errors`."""
    return mm_errors(pred, futures, idx, mask, batch_size=batch_size)[0]


@_checked
def mmfde(
    pred: Float[ArrayLike, "n k t d"],
    futures: Float[ArrayLike, "r t d"],
    idx: Int[ArrayLike, "n m"],
    mask: Bool[ArrayLike, "n m"],
    *,
    batch_size: int = 16,
) -> Float[Array, " n"]:
    """Returns per-window MMFDE `mean_{m in MM(i)} min_k ||Yhat_{k,T} - Y_{m,T}||` ([protocol §2][metrics]); see `mm_errors`."""
    return mm_errors(pred, futures, idx, mask, batch_size=batch_size)[1]


# --------------------------------------------------------------------------------------------
# Streaming evaluation.


@partial(jax.jit, static_argnames="parents")
def _chunk_metrics(pred, gt, futures, idx, mask, targets=None, parents=None):
    ade_k = _ade_terms(pred, gt)
    fde_k = _fde_terms(pred, gt)
    mm_ade, mm_fde = _mm_batch(pred, idx, mask, futures, targets, parents)
    return {
        "APD": _apd(pred),
        "ADE": jnp.min(ade_k, axis=-1),
        "FDE": jnp.min(fde_k, axis=-1),
        "MMADE": mm_ade,
        "MMFDE": mm_fde,
        "ADE-m": jnp.median(ade_k, axis=-1),
        "FDE-m": jnp.median(fde_k, axis=-1),
    }


def _piece(piece) -> np.ndarray | jax.Array:
    # One (n_c, K, t_pred, D) piece of the predictions, as an array.
    piece = piece if hasattr(piece, "shape") else np.asarray(piece)
    if piece.ndim != 4:
        raise ValueError(f"evaluate_windows: `pred` (or a chunk of it) must be (n, K, t_pred, D), got {tuple(piece.shape)}")
    return piece


def _pieces(pred) -> Iterator[np.ndarray | jax.Array]:
    # `pred` as a sequence of (n_c, K, t_pred, D) pieces: the whole array is one piece.
    for piece in [pred] if hasattr(pred, "shape") else pred:
        yield _piece(piece)


class WindowMetricStream:
    """Every per-window metric of [protocol §2][metrics] over predictions that arrive in pieces, in window order.

    `add(piece)` takes the next `(n_c, K, t_pred, D)` predictions; `result()` returns the `(N,)`
    numpy arrays keyed as `METRIC_NAMES` once every window has arrived. Windows are evaluated in
    chunks of the first piece's size (at most `chunk_size`), the last one padded, so the jitted
    kernel compiles once per (K, chunk size) and no time goes to padding when the pieces come in
    a fixed size. See `window_metrics` for the arguments.
    """

    def __init__(self, gt, futures, idx, mask, *, chunk_size: int = 32, transfer_poses=None, transfer_parents=None):
        fn = "window_metrics"
        _check_finite(fn, "gt", gt)
        if (transfer_poses is None) != (transfer_parents is None):
            raise ValueError(f"{fn}: give both `transfer_poses` and `transfer_parents`, or neither")
        if transfer_parents is not None:
            transfer_parents = tuple(int(q) for q in transfer_parents)
            frame_parents(transfer_parents)
            transfer_poses = np.asarray(transfer_poses, np.float32)
            _check_finite(fn, "transfer_poses", transfer_poses)
            _check_same(fn, "number of windows", "transfer_poses", transfer_poses.shape[0], "gt", np.shape(gt)[0])
        _check_finite(fn, "futures", futures)
        _check_idx(fn, idx, mask, futures.shape[0])
        self.gt = np.asarray(gt, np.float32)
        self.futures = jnp.asarray(futures, jnp.float32)
        self.idx, self.mask = np.asarray(idx, np.int32), np.asarray(mask, bool)
        self.transfer_poses, self.transfer_parents = transfer_poses, transfer_parents
        self.chunk_size = chunk_size
        n = self.gt.shape[0]
        self.out = {k: np.empty((n,), np.float32) for k in METRIC_NAMES}
        self.start, self.k_seen, self.size = 0, None, None

    def add(self, piece) -> None:
        """Scores the next `(n_c, K, t_pred, D)` predictions (windows `[seen, seen + n_c)`)."""
        for chunk in self._chunks(_piece(piece)):
            self._chunk(chunk)

    def _chunks(self, piece):
        # Chunks are at most as long as the first piece (and `chunk_size`), so that pieces arriving
        # in a fixed size (a sampler's batches) pass through unsplit and only the last one is padded.
        if self.size is None and piece.shape[0]:
            self.size = min(self.chunk_size, piece.shape[0])
        for s in range(0, piece.shape[0], self.size or 1):
            yield piece[s : s + self.size]

    def _chunk(self, chunk) -> None:
        fn, gt, n = "window_metrics", self.gt, self.gt.shape[0]
        c, start = chunk.shape[0], self.start
        if start + c > n:
            raise ValueError(f"{fn}: `pred` has more windows than `gt` ({n})")
        if self.k_seen is None:
            self.k_seen = chunk.shape[1]
        _check_same(fn, "K", "pred chunk", chunk.shape[1], "first pred chunk", self.k_seen)
        _check_same(fn, "t_pred", "pred", chunk.shape[2], "gt", gt.shape[1])
        _check_same(fn, "D", "pred", chunk.shape[3], "gt", gt.shape[2])
        if not np.all(np.isfinite(np.asarray(chunk))):
            raise ValueError(f"{fn}: `pred` contains NaN or inf in windows [{start}, {start + c})")
        sl = slice(start, start + c)
        pad = self.size - c
        args = [np.asarray(chunk, np.float32), gt[sl], self.idx[sl], self.mask[sl]]
        if self.transfer_parents is not None:
            args.append(self.transfer_poses[sl])
        if pad:
            args = [np.concatenate([a, np.zeros((pad,) + a.shape[1:], a.dtype)]) for a in args]
        p, g, i, m = args[:4]
        targets = jnp.asarray(args[4]) if self.transfer_parents is not None else None
        res = _chunk_metrics(jnp.asarray(p), jnp.asarray(g), self.futures, jnp.asarray(i), jnp.asarray(m), targets,
                             self.transfer_parents)
        for key in METRIC_NAMES:
            self.out[key][sl] = np.asarray(res[key])[:c]
        self.start += c

    def result(self) -> dict[str, np.ndarray]:
        """Returns the `(N,)` per-window metrics; every window must have arrived."""
        if self.start != self.gt.shape[0]:
            raise ValueError(f"window_metrics: `pred` has {self.start} windows but `gt` has {self.gt.shape[0]}")
        return self.out


@_checked
def window_metrics(
    pred: Float[ArrayLike, "n k t d"] | Iterable[Float[ArrayLike, "c k t d"]],
    gt: Float[ArrayLike, "n t d"],
    futures: Float[ArrayLike, "r t d"],
    idx: Int[ArrayLike, "n m"],
    mask: Bool[ArrayLike, "n m"],
    *,
    chunk_size: int = 32,
    transfer_poses: Float[ArrayLike, "n d"] | None = None,
    transfer_parents: tuple[int, ...] | None = None,
) -> dict[str, np.ndarray]:
    """Returns every per-window metric of [protocol §2][metrics] as `(N,)` numpy arrays, keyed as `METRIC_NAMES`.

    `pred` is either the whole `(N, K, t_pred, D)` array or an iterable of `(n_c, K, t_pred, D)`
    chunks whose concatenation along axis 0 is that array (e.g. a generator that samples the model
    chunk by chunk), so the full prediction tensor never needs to exist (`WindowMetricStream`).
    MM futures are `futures[idx]` where `mask` holds.

    With `transfer_parents` (the skeleton's parents, root first) and `transfer_poses` (each window's
    last observed pose), every MM future is motion-transferred onto the window's skeleton before
    MMADE / MMFDE (MotionMap's evaluation, [protocol §2][metrics] option; `motion_transfer`).
    """
    stream = WindowMetricStream(gt, futures, idx, mask, chunk_size=chunk_size, transfer_poses=transfer_poses,
                                transfer_parents=transfer_parents)
    for piece in _pieces(pred):
        stream.add(piece)
    return stream.result()


# --------------------------------------------------------------------------------------------
# Synthetic data with known modes.


def _recall_one(pred, modes, probs, mask, thr):
    d = jnp.mean(jnp.sqrt(jnp.sum((pred[:, None] - modes[None]) ** 2, axis=-1)), axis=-1)  # (K, P)
    d = jnp.where(mask[None], d, jnp.inf)
    nearest = jnp.argmin(d, axis=1)
    close = jnp.min(d, axis=1) < thr
    # Each sample counts only for its nearest valid mode, so one sample never reaches two modes.
    reached = jnp.any((nearest[:, None] == jnp.arange(d.shape[1])[None]) & close[:, None], axis=0) & mask
    recall = jnp.sum(reached) / jnp.sum(mask)
    weighted = jnp.sum(jnp.where(reached, probs, 0.0)) / jnp.sum(jnp.where(mask, probs, 0.0))
    return recall, weighted


@partial(jax.jit, static_argnames="batch_size")
def _mode_recall(pred, modes, probs, mask, thr, batch_size):
    return lax.map(lambda a: _recall_one(*a, thr), (pred, modes, probs, mask), batch_size=batch_size)


@_checked
def mode_recall(
    pred: Float[ArrayLike, "n k t d"],
    modes: Float[ArrayLike, "n p t d"],
    mode_probs: Float[ArrayLike, "n p"] | Float[ArrayLike, " p"],
    mode_mask: Bool[ArrayLike, "n p"] | None,
    thr: float | Float[ArrayLike, ""],
    *,
    batch_size: int = 16,
) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Returns per-window `(recall, weighted_recall)` of known future modes (synthetic data; [protocol §2][metrics] ADE term).

    Each sample is assigned to its nearest valid mode by the ADE term
    `(1/T) sum_t ||Yhat_{k,t} - mode_{p,t}||`; a mode is reached when at least one sample assigned
    to it is closer than `thr`. The assignment makes a sample count for one mode at most, however
    large `thr` is; `recall` is the fraction of valid modes reached, `weighted_recall` the
    probability mass of reached modes over that of valid modes. `thr` (metres) is deliberately
    required: the right value depends on how far apart the dataset's modes are, and it must be
    reported next to the numbers. A window with no valid mode gives NaN.

    `mode_probs` may be `(P,)` when every window shares the prior (as `data.synthetic.TestModes`
    does), and `mode_mask=None` means every mode is valid.
    """
    fn = "mode_recall"
    if not _is_traced(thr) and (not np.isfinite(thr) or thr <= 0):
        raise ValueError(f"{fn}: `thr` must be a positive finite distance, got {thr}")
    for name, x in (("pred", pred), ("modes", modes), ("mode_probs", mode_probs)):
        _check_finite(fn, name, x)
    n, p = modes.shape[:2]
    if mode_probs.ndim == 1:
        mode_probs = jnp.broadcast_to(jnp.asarray(mode_probs), (n, p))
    if mode_mask is None:
        mode_mask = jnp.ones((n, p), bool)
    return _mode_recall(
        jnp.asarray(pred, jnp.float32),
        jnp.asarray(modes, jnp.float32),
        jnp.asarray(mode_probs, jnp.float32),
        jnp.asarray(mode_mask, bool),
        jnp.float32(thr),
        batch_size,
    )
