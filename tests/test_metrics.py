"""Tests of jaxmotion.eval.metrics against hand-computed values, properties and a loop reference (protocol §2 (docs/pages/protocol.md#metrics))."""

from __future__ import annotations

import itertools

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jaxtyping import TypeCheckError

from jaxmotion.eval import metrics as M
from jaxmotion.eval import evaluate_windows

# Every new shape recompiles, so examples are few and shapes come from a small range.
PROPS = settings(max_examples=10, deadline=None)

# ---------------------------------------------------------------------------------------------
# Hand-computed case: N = 3 windows, K = 2, t_pred = 2, D = 2, built from 3-4-5 triangles.
#
# Last poses c_0 = (0, 0), c_1 = (3, 4), c_2 = (100, 0); thr = 6:
#   ||c_0 - c_1|| = 5 < 6, c_2 is far  ->  MM(0) = MM(1) = {0, 1}, MM(2) = {2}.
# Ground truth: Y_0 = [(0,0), (0,0)], Y_1 = [(3,4), (6,8)], Y_2 = [(1,1), (1,1)].
#
# Window 0: Yhat_0 = [(0,0), (3,4)], Yhat_1 = [(0,0), (9,12)]
#   APD: vec diff = (0,0,-6,-8) -> 10.
#   vs Y_0: frame dists k0 [0, 5] -> ADE-term 2.5, FDE-term 5; k1 [0, 15] -> 7.5, 15.
#     ADE 2.5, FDE 5, ADE-m (2.5+7.5)/2 = 5, FDE-m (5+15)/2 = 10.
#   vs Y_1: k0 [5, 5] -> 5, 5; k1 [5, 5] -> 5, 5.   min: 5, 5.
#   MMADE = (2.5 + 5)/2 = 3.75, MMFDE = (5 + 5)/2 = 5.
# Window 1: Yhat_0 = [(3,4), (6,8)] (= Y_1), Yhat_1 = [(3,4), (0,0)]
#   APD: vec diff = (0,0,6,8) -> 10.
#   vs Y_1: k0 [0, 0] -> 0, 0; k1 [0, 10] -> 5, 10.  ADE 0, FDE 0, ADE-m 2.5, FDE-m 5.
#   vs Y_0: k0 [5, 10] -> 7.5, 10; k1 [5, 0] -> 2.5, 0.  min ADE 2.5, min FDE 0 (different k).
#   MMADE = (0 + 2.5)/2 = 1.25, MMFDE = (0 + 0)/2 = 0.
# Window 2: Yhat_0 = [(1,1), (1,1)] (= Y_2), Yhat_1 = [(4,5), (1,1)]
#   APD: vec diff = (-3,-4,0,0) -> 5.
#   vs Y_2: k0 [0, 0] -> 0, 0; k1 [5, 0] -> 2.5, 0.  ADE 0, FDE 0, ADE-m 1.25, FDE-m 0.
#   MMADE = MMFDE = 0.
# Averages (protocol): APD 25/3, ADE 2.5/3, FDE 5/3, ADE-m 8.75/3, FDE-m 15/3,
#   MMADE (3.75+1.25+0)/3 = 5/3, MMFDE (5+0+0)/3 = 5/3.
# DivSamp's release: MM'(i) = MM(i) (no duplicate last poses here); window 2 has no neighbour, so
#   it is skipped in all five metrics and the sums are divided by 3: APD 20/3, ADE 2.5/3, FDE 5/3,
#   MMADE (3.75+1.25)/3 = 5/3, MMFDE (5+0)/3 = 5/3.
# CoMusion: window 2 (only itself) dropped: MMADE (3.75+1.25)/2 = 2.5, MMFDE (5+0)/2 = 2.5.

LAST = np.array([[0, 0], [3, 4], [100, 0]], np.float32)
GT = np.array([[[0, 0], [0, 0]], [[3, 4], [6, 8]], [[1, 1], [1, 1]]], np.float32)
PRED = np.array(
    [
        [[[0, 0], [3, 4]], [[0, 0], [9, 12]]],
        [[[3, 4], [6, 8]], [[3, 4], [0, 0]]],
        [[[1, 1], [1, 1]], [[4, 5], [1, 1]]],
    ],
    np.float32,
)
THR = 6.0


def test_hand_computed_per_window():
    np.testing.assert_allclose(M.apd(PRED), [10, 10, 5], atol=1e-6)
    np.testing.assert_allclose(M.ade(PRED, GT), [2.5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(M.fde(PRED, GT), [5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(M.ade_median(PRED, GT), [5, 2.5, 1.25], atol=1e-6)
    np.testing.assert_allclose(M.fde_median(PRED, GT), [10, 5, 0], atol=1e-6)
    idx, mask = M.multimodal_gt(LAST, THR)
    assert [sorted(np.asarray(i)[np.asarray(m)].tolist()) for i, m in zip(idx, mask)] == [[0, 1], [0, 1], [2]]
    np.testing.assert_allclose(M.mmade(PRED, GT, idx, mask), [3.75, 1.25, 0], atol=1e-6)
    np.testing.assert_allclose(M.mmfde(PRED, GT, idx, mask), [5, 0, 0], atol=1e-6)


@pytest.mark.parametrize(
    "deviation, mmade, mmfde, n_avg",
    [(None, 5 / 3, 5 / 3, 3), ("divsamp", 5 / 3, 5 / 3, 2), ("comusion", 2.5, 2.5, 2)],
)
def test_hand_computed_aggregates(deviation, mmade, mmfde, n_avg):
    out = evaluate_windows(PRED, GT, LAST, thr=THR, mm_deviation=deviation, chunk_size=2)
    expected = {"APD": 25 / 3, "ADE": 2.5 / 3, "FDE": 5 / 3, "ADE-m": 8.75 / 3, "FDE-m": 5.0}
    if deviation == "divsamp":
        expected["APD"] = 20 / 3  # window 2, with no neighbour, is skipped and the sum divided by 3
    expected.update(MMADE=mmade, MMFDE=mmfde, MM_n_averaged=n_avg, n_windows=3)
    expected.update(MM_mean=5 / 3, MM_min=1, MM_max=2, MM_only_self_frac=1 / 3)
    for key, value in expected.items():
        assert out[key] == pytest.approx(value, abs=1e-6), key


def test_exclude_self_sets():
    idx, mask = M.multimodal_gt(LAST, THR, exclude_self=True)
    members = [np.asarray(i)[np.asarray(m)].tolist() for i, m in zip(idx, mask)]
    assert members == [[1], [0], []]
    # An empty set has no MMADE; the aggregation decides (see reduce_mm).
    assert np.isnan(np.asarray(M.mmade(PRED, GT, idx, mask))[2])


def test_reference_windows():
    # Reference (e.g. training) windows: r_0 = (0, 1) is within 6 of c_0 and of c_1 (sqrt(18)),
    # r_1 is far from all. R_0 = Y_0, so MMADE(0) = ADE-term(window 0 vs Y_0) = 2.5 and
    # MMADE(1) = 2.5 (see above); MMFDE 5 and 0. Window 2 has an empty set and is not averaged.
    ref_last = np.array([[0, 1], [50, 50]], np.float32)
    ref_fut = np.stack([GT[0], GT[2] + 40])
    idx, mask = M.multimodal_gt(LAST, THR, reference_last_poses=ref_last)
    assert np.asarray(mask).sum(1).tolist() == [1, 1, 0]
    out = evaluate_windows(
        PRED, GT, LAST, thr=THR, reference_last_poses=ref_last, reference_futures=ref_fut
    )
    assert out["MMADE"] == pytest.approx(2.5, abs=1e-6)
    assert out["MMFDE"] == pytest.approx(2.5, abs=1e-6)
    assert out["MM_n_averaged"] == 2
    assert out["MM_only_self_frac"] == pytest.approx(1 / 3)
    assert out["ADE"] == pytest.approx(2.5 / 3, abs=1e-6)


def test_apd_single_sample_is_zero():
    np.testing.assert_array_equal(M.apd(PRED[:, :1]), [0, 0, 0])


# ---------------------------------------------------------------------------------------------
# Properties.

dims = st.tuples(
    st.integers(1, 4),  # N
    st.integers(1, 3),  # K
    st.integers(1, 2),  # t_pred
    st.integers(1, 3),  # D
)


def _random(seed, n, k, t, d):
    rng = np.random.default_rng(seed)
    pred = rng.normal(size=(n, k, t, d)).astype(np.float32)
    gt = rng.normal(size=(n, t, d)).astype(np.float32)
    last = rng.normal(size=(n, d)).astype(np.float32)
    return rng, pred, gt, last


@PROPS
@given(dims, st.integers(0, 2**31 - 1))
def test_apd_permutation_invariant(shape, seed):
    rng, pred, _, _ = _random(seed, *shape)
    perm = rng.permutation(shape[1])
    np.testing.assert_allclose(M.apd(pred), M.apd(pred[:, perm]), rtol=1e-5, atol=1e-6)


@PROPS
@given(dims, st.integers(0, 2**31 - 1))
def test_apd_zero_for_identical_samples(shape, seed):
    _, pred, _, _ = _random(seed, *shape)
    same = np.repeat(pred[:, :1], shape[1], axis=1)
    np.testing.assert_array_equal(M.apd(same), np.zeros(shape[0]))


@PROPS
@given(dims, st.integers(0, 2**31 - 1))
def test_ade_fde_zero_when_a_sample_is_the_ground_truth(shape, seed):
    rng, pred, gt, _ = _random(seed, *shape)
    hit = rng.integers(shape[1])
    pred[:, hit] = gt
    np.testing.assert_array_equal(M.ade(pred, gt), np.zeros(shape[0]))
    np.testing.assert_array_equal(M.fde(pred, gt), np.zeros(shape[0]))


@PROPS
@given(dims, st.integers(0, 2**31 - 1), st.floats(0.01, 3.0))
def test_mm_set_contains_self(shape, seed, thr):
    _, _, _, last = _random(seed, *shape)
    last[-1] = last[0]  # a duplicated pose must not displace anyone's self-membership
    idx, mask = (np.asarray(a) for a in M.multimodal_gt(last, thr))
    for i in range(shape[0]):
        assert i in idx[i][mask[i]]
    idx_x, mask_x = (np.asarray(a) for a in M.multimodal_gt(last, thr, exclude_self=True))
    np.testing.assert_array_equal(mask_x.sum(1), mask.sum(1) - 1)
    assert all(i not in idx_x[i][mask_x[i]] for i in range(shape[0]))


@PROPS
@given(dims, st.integers(0, 2**31 - 1))
def test_mmade_equals_ade_when_only_self(shape, seed):
    _, pred, gt, last = _random(seed, *shape)
    last += 10.0 * np.arange(shape[0], dtype=np.float32)[:, None]  # windows far apart
    idx, mask = M.multimodal_gt(last, 1e-6)
    assert np.asarray(mask).sum() == shape[0]
    np.testing.assert_allclose(M.mmade(pred, gt, idx, mask), M.ade(pred, gt), rtol=1e-6)
    np.testing.assert_allclose(M.mmfde(pred, gt, idx, mask), M.fde(pred, gt), rtol=1e-6)


@settings(max_examples=6, deadline=None)
@given(dims, st.integers(0, 2**31 - 1), st.integers(1, 3), st.sampled_from([None, "divsamp", "comusion"]))
def test_chunked_equals_unchunked(shape, seed, chunk, deviation):
    _, pred, gt, last = _random(seed, *shape)
    whole = evaluate_windows(pred, gt, last, thr=1.5, mm_deviation=deviation, chunk_size=64)
    # Uneven incoming pieces, re-chunked and padded inside.
    cuts = list(range(0, shape[0], 2)) + [shape[0]]
    pieces = (pred[a:b] for a, b in zip(cuts[:-1], cuts[1:]))
    streamed = evaluate_windows(pieces, gt, last, thr=1.5, mm_deviation=deviation, chunk_size=chunk)
    assert whole.keys() == streamed.keys()
    for key in whole:
        np.testing.assert_allclose(streamed[key], whole[key], rtol=1e-6, atol=1e-6, err_msg=key)


# ---------------------------------------------------------------------------------------------
# Loop reference, written like DLow's numpy evaluation code.


def _reference(pred, gt, last, thr, deviation=None):
    pred, gt, last = (np.asarray(a, np.float64) for a in (pred, gt, last))
    n, k = pred.shape[:2]
    apd, ade, fde, adem, fdem, mmade, mmfde, others = [], [], [], [], [], [], [], []
    for i in range(n):
        flat = pred[i].reshape(k, -1)
        pairs = [np.linalg.norm(flat[a] - flat[b]) for a, b in itertools.combinations(range(k), 2)]
        apd.append(np.mean(pairs) if pairs else 0.0)
        dist = np.linalg.norm(pred[i] - gt[i], axis=-1)
        ade.append(dist.mean(1).min())
        fde.append(dist[:, -1].min())
        adem.append(np.median(dist.mean(1)))
        fdem.append(np.median(dist[:, -1]))
        members = [j for j in range(n) if np.linalg.norm(last[i] - last[j]) < thr]
        if deviation == "divsamp":  # the release: itself, plus neighbours whose last pose differs from its own
            members = [i] + [j for j in members if j != i and np.any(last[j] != last[i])]
        others.append(len(members) - 1)
        a = [np.linalg.norm(pred[i] - gt[j], axis=-1).mean(1).min() for j in members]
        f = [np.linalg.norm(pred[i, :, -1] - gt[j, -1], axis=-1).min() for j in members]
        mmade.append(np.mean(a) if members else np.nan)
        mmfde.append(np.mean(f) if members else np.nan)
    out = {"APD": np.mean(apd), "ADE": np.mean(ade), "FDE": np.mean(fde)}
    out.update({"ADE-m": np.mean(adem), "FDE-m": np.mean(fdem)})
    mmade, mmfde, others = np.array(mmade), np.array(mmfde), np.array(others)
    if deviation is None:
        out.update(MMADE=mmade.mean(), MMFDE=mmfde.mean())
    elif deviation == "divsamp":
        keep = others > 0
        out.update({key: np.sum(np.array(v)[keep]) / n for key, v in (("APD", apd), ("ADE", ade), ("FDE", fde))})
        out.update(MMADE=np.sum(mmade[keep]) / n, MMFDE=np.sum(mmfde[keep]) / n)
    else:
        keep = others > 0
        out.update(MMADE=mmade[keep].mean(), MMFDE=mmfde[keep].mean())
    return out


@pytest.mark.parametrize("deviation", [None, "divsamp", "comusion"])
def test_matches_loop_reference(deviation):
    rng = np.random.default_rng(7)
    n, k, t, d = 24, 5, 4, 6
    # Clustered last poses so that MM sets have several members and some have only themselves.
    centres = rng.normal(scale=3.0, size=(6, d))
    last = (centres[rng.integers(6, size=n)] + rng.normal(scale=0.3, size=(n, d))).astype(np.float32)
    last[-1] += 100.0
    gt = rng.normal(size=(n, t, d)).astype(np.float32)
    pred = (gt[:, None] + rng.normal(scale=0.5, size=(n, k, t, d))).astype(np.float32)
    got = evaluate_windows(pred, gt, last, thr=1.0, mm_deviation=deviation, chunk_size=5)
    want = _reference(pred, gt, last, 1.0, deviation)
    assert got["MM_max"] > 2 and got["MM_only_self_frac"] > 0
    for key, value in want.items():
        assert got[key] == pytest.approx(value, rel=1e-5), key


def test_per_window_functions_jit():
    idx, mask = M.multimodal_gt(LAST, THR)
    f = jax.jit(lambda p, g, i, m: (M.apd(p), M.ade(p, g), M.mmade(p, g, i, m)))
    apd, ade, mmade = f(PRED, GT, idx, mask)
    np.testing.assert_allclose(apd, [10, 10, 5], atol=1e-6)
    np.testing.assert_allclose(ade, [2.5, 0, 0], atol=1e-6)
    np.testing.assert_allclose(mmade, [3.75, 1.25, 0], atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Mode recall on fabricated modes: T = 2, D = 1, P = 3.
#   Window 0: modes 0, 10, -10 (the last invalid), probs 0.6, 0.2, 0.2. Samples 0.5 (ADE 0.5
#   to mode 0) and 5 (ADE 5 to modes 0 and 10). thr = 1: reached {0}; recall 1/2,
#   weighted 0.6 / (0.6 + 0.2) = 0.75.
#   Window 1: all valid, probs 0.2, 0.3, 0.5. Samples [9.5, 10.5] (ADE 0.5 to mode 10) and
#   [-10, -9] (ADE 0.5 to mode -10): reached {10, -10}; recall 2/3, weighted 0.8.


def test_mode_recall():
    modes = np.broadcast_to(np.array([0.0, 10.0, -10.0])[None, :, None, None], (2, 3, 2, 1))
    probs = np.array([[0.6, 0.2, 0.2], [0.2, 0.3, 0.5]])
    valid = np.array([[True, True, False], [True, True, True]])
    pred = np.array([[[[0.5], [0.5]], [[5.0], [5.0]]], [[[9.5], [10.5]], [[-10.0], [-9.0]]]])
    recall, weighted = M.mode_recall(pred, modes, probs, valid, 1.0)
    np.testing.assert_allclose(recall, [1 / 2, 2 / 3], atol=1e-6)
    np.testing.assert_allclose(weighted, [0.75, 0.8], atol=1e-6)
    recall, _ = M.mode_recall(pred, modes, probs, valid, 0.5)  # strict: ADE 0.5 is not < 0.5
    np.testing.assert_allclose(recall, [0, 0], atol=1e-6)
    with pytest.raises(TypeCheckError, match="parameter 'thr'"):
        M.mode_recall(pred, modes, probs, valid, None)
    with pytest.raises(ValueError, match="thr"):
        M.mode_recall(pred, modes, probs, valid, -1.0)
    # A shared (P,) prior and no mask: window 0 now has mode -10 valid too (not reached).
    recall, weighted = M.mode_recall(pred, modes, probs[1], None, 1.0)
    np.testing.assert_allclose(recall, [1 / 3, 2 / 3], atol=1e-6)
    np.testing.assert_allclose(weighted, [0.2, 0.8], atol=1e-6)


def test_mode_recall_counts_a_sample_for_its_nearest_mode_only():
    modes = np.array([0.0, 1.0])[None, :, None, None] * np.ones((1, 2, 3, 1))
    one = np.full((1, 1, 3, 1), 0.4)  # within thr of both modes, nearer to mode 0
    recall, weighted = M.mode_recall(one, modes, np.array([0.7, 0.3]), None, 1.0)
    np.testing.assert_allclose(recall, [0.5])
    np.testing.assert_allclose(weighted, [0.7])
    two = np.concatenate([one, np.full((1, 1, 3, 1), 0.9)], axis=1)
    recall, _ = M.mode_recall(two, modes, np.array([0.7, 0.3]), None, 1.0)
    np.testing.assert_allclose(recall, [1.0])


# ---------------------------------------------------------------------------------------------
# Boundary validation.


def test_validation_names_the_argument():
    # Values: hand-written ValueErrors.
    bad = PRED.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="`pred` contains NaN"):
        M.ade(bad, GT)
    with pytest.raises(ValueError, match="`pred` contains NaN"):
        evaluate_windows(bad, GT, LAST, thr=THR)
    with pytest.raises(ValueError, match="`last_poses` contains NaN"):
        M.multimodal_gt(np.full((2, 2), np.nan), THR)
    with pytest.raises(ValueError, match="`thr` is required"):
        evaluate_windows(PRED, GT, LAST)
    with pytest.raises(ValueError, match="`pred` has 2 windows"):
        evaluate_windows(iter([PRED[:1], PRED[1:2]]), GT, LAST, thr=THR)
    with pytest.raises(ValueError, match="`idx` has entries outside"):
        M.mm_errors(PRED, GT, np.full((3, 1), 3), np.ones((3, 1), bool))
    # Shapes and literals: the annotations, checked in production too (`jaxtyped` + beartype on the
    # public entry points), name the argument and the axis sizes already bound.
    with pytest.raises(TypeCheckError, match=r"(?s)parameter 'gt'.*f32\[2,2\]"):
        M.ade(PRED, GT[0])
    with pytest.raises(TypeCheckError, match=r"(?s)parameter 'gt'.*\nt=2\n"):
        M.fde(PRED, GT[:, :1])
    with pytest.raises(TypeCheckError, match=r"(?s)parameter 'reference_last_poses'.*\nd=2\n"):
        M.multimodal_gt(LAST, THR, reference_last_poses=np.zeros((4, 3)))
    with pytest.raises(TypeCheckError, match=r"(?s)parameter 'gt'.*\nn=2\n"):
        evaluate_windows(PRED[:2], GT, LAST, thr=THR)
    with pytest.raises(TypeCheckError, match="parameter 'mask'"):
        M.mm_errors(PRED, GT, np.zeros((3, 1), int), np.ones((3, 2), bool))
    with pytest.raises(TypeCheckError, match="parameter 'mm_deviation'"):
        evaluate_windows(PRED, GT, LAST, thr=THR, mm_deviation="dlow")
    with pytest.raises(TypeCheckError, match="parameter 'pred'"):
        M.apd(np.zeros((3, 2, 2), int))


def test_divsamp_deviation_drops_duplicate_last_poses_and_differs_from_the_protocol():
    # Windows 0 and 3 have the same last pose, 1 is near them, 2 is alone (thr 0.5).
    last = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 0.0], [0.0, 0.0]], np.float32)
    gt = np.array([[[0, 0]], [[1, 0]], [[9, 9]], [[0, 3]]], np.float32)  # one future frame each
    pred = np.array([[[[0, 0]]], [[[1, 0]]], [[[9, 9]]], [[[0, 3]]]], np.float32)  # K = 1, exact
    proto = evaluate_windows(pred, gt, last, thr=0.5)
    rel = evaluate_windows(pred, gt, last, thr=0.5, mm_deviation="divsamp")
    d = lambda i, j: float(np.linalg.norm(gt[i, 0] - gt[j, 0]))  # noqa: E731
    # Protocol: MM(0) = MM(1) = MM(3) = {0, 1, 3}, MM(2) = {2}; averaged over 4 windows.
    want = (np.mean([d(0, 0), d(0, 1), d(0, 3)]) + np.mean([d(1, 0), d(1, 1), d(1, 3)]) + 0 + np.mean([d(3, 0), d(3, 1), d(3, 3)])) / 4
    assert proto["MMADE"] == pytest.approx(want, rel=1e-6) and proto["ADE"] == 0
    # Release: MM'(0) = {0, 1} (3 is a duplicate), MM'(1) = {1, 0, 3}, MM'(3) = {3, 1}; 2 skipped; / 4.
    want = (np.mean([d(0, 0), d(0, 1)]) + np.mean([d(1, 1), d(1, 0), d(1, 3)]) + np.mean([d(3, 3), d(3, 1)])) / 4
    assert rel["MMADE"] == pytest.approx(want, rel=1e-6) and rel["MM_n_averaged"] == 3
    assert rel["MMADE"] != pytest.approx(proto["MMADE"], rel=1e-3)
    with pytest.raises(ValueError, match="divsamp.*last poses"):
        evaluate_windows(pred, gt, M.multimodal_gt(last, 0.5), mm_deviation="divsamp")
