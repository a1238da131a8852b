"""The matrix-product forms of APD and MMADE / MMFDE (jaxmotion.eval.metrics) against their definitions (protocol §2 (docs/pages/protocol.md#metrics)).

APD and the multimodal terms are computed from `|a|^2 + |b|^2 - 2 a.b` (one product per window or
per block of set members) rather than from explicit differences; these tests compare them with
plain float64 loops written from the protocol, on data placed far from the origin (where the
product form would lose digits without its centring), with duplicate samples, K = 1, masked
entries, empty sets and set sizes that take several member blocks.
"""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.eval import metrics as M


def _apd_loop(pred):
    out = []
    for w in np.asarray(pred, np.float64):
        flat = w.reshape(w.shape[0], -1)
        pairs = [np.linalg.norm(flat[i] - flat[j]) for i, j in itertools.combinations(range(len(flat)), 2)]
        out.append(np.mean(pairs) if pairs else 0.0)
    return np.array(out)


def _mm_loop(pred, futures, idx, mask):
    pred, futures = np.asarray(pred, np.float64), np.asarray(futures, np.float64)
    ade, fde = [], []
    for p, i, m in zip(pred, idx, mask):
        members = [futures[j] for j, keep in zip(i, m) if keep]
        a = [np.linalg.norm(p - f, axis=-1).mean(1).min() for f in members]
        e = [np.linalg.norm(p[:, -1] - f[-1], axis=-1).min() for f in members]
        ade.append(np.mean(a) if members else np.nan)
        fde.append(np.mean(e) if members else np.nan)
    return np.array(ade), np.array(fde)


def _poses(rng, *shape, offset=50.0):
    # Metre-scale motion 50 m from the origin: |x|^2 is ~10^4 times the squared distances.
    return (offset + rng.normal(scale=0.3, size=shape)).astype(np.float32)


def test_apd_matches_the_pairwise_definition_far_from_the_origin():
    rng = np.random.default_rng(0)
    pred = _poses(rng, 3, 40, 8, 9)
    np.testing.assert_allclose(M.apd(pred), _apd_loop(pred), rtol=2e-6)


def test_apd_in_blocks_matches_the_pairwise_definition(monkeypatch):
    # Blocks of 4 samples (K = 10: three blocks, two padding rows), duplicates within and across blocks.
    rng = np.random.default_rng(4)
    pred = _poses(rng, 2, 10, 4, 6)
    pred[0, 9], pred[1, 2] = pred[0, 5], pred[1, 3]
    monkeypatch.setattr(M, "APD_BLOCK", 4)
    apd = jax.jit(jax.vmap(M._apd_window))  # a fresh trace, so the block size above applies
    np.testing.assert_allclose(apd(jnp.asarray(pred.reshape(2, 10, -1))), _apd_loop(pred), rtol=2e-6)


def test_apd_duplicates_are_zero_distance_with_finite_gradients():
    rng = np.random.default_rng(1)
    pred = _poses(rng, 2, 6, 5, 3)
    pred[0, 4] = pred[0, 1]  # one duplicate pair (neither is sample 0)
    pred[1] = pred[1, :1]  # every sample identical
    got = np.asarray(M.apd(pred))
    np.testing.assert_allclose(got[0], _apd_loop(pred[:1])[0], rtol=2e-6)
    assert got[1] == 0.0
    grad = jax.grad(lambda p: jnp.sum(M.apd(p)))(jnp.asarray(pred))
    assert np.all(np.isfinite(np.asarray(grad)))
    # K = 1: no pair, APD 0, gradient 0.
    one = jnp.asarray(pred[:, :1])
    assert np.all(np.asarray(M.apd(one)) == 0.0)
    assert np.all(np.asarray(jax.grad(lambda p: jnp.sum(M.apd(p)))(one)) == 0.0)


@pytest.mark.parametrize("block_elems", [M.MM_BLOCK_ELEMS, 1])  # 1: blocks of 8 members, several per window
def test_mm_terms_match_a_numpy_loop(monkeypatch, block_elems):
    rng = np.random.default_rng(2)
    n, k, t, d, r, m = 5, 7, 6, 9, 30, 20
    futures = _poses(rng, r, t, d)
    pred = _poses(rng, n, k, t, d)
    pred[1, 3] = futures[4]  # a sample equal to its window's first member: that term is exactly 0
    idx = rng.integers(r, size=(n, m)).astype(np.int32)
    idx[1, 0] = 4
    counts = [20, 9, 1, 0, 13]  # a full set, sizes across block edges, a single member, an empty set
    mask = np.arange(m)[None] < np.array(counts)[:, None]
    idx[~mask] = rng.integers(r, size=(~mask).sum())  # masked entries point anywhere and must not count
    monkeypatch.setattr(M, "MM_BLOCK_ELEMS", block_elems)
    f = jax.jit(lambda *a: M._mm_batch(*a))  # a fresh trace, so the block size above applies
    ade, fde = (np.asarray(v) for v in f(jnp.asarray(pred), jnp.asarray(idx), jnp.asarray(mask), jnp.asarray(futures)))
    want_ade, want_fde = _mm_loop(pred, futures, idx, mask)
    np.testing.assert_allclose(ade, want_ade, rtol=1e-5)
    np.testing.assert_allclose(fde, want_fde, rtol=1e-5)
    assert np.isnan(ade[3]) and np.isnan(fde[3])  # empty set: NaN, left to the aggregation (reduce_mm)


def test_mm_errors_k1_with_exact_hits():
    rng = np.random.default_rng(3)
    futures = _poses(rng, 4, 5, 6)
    pred = jnp.asarray(futures[:3, None])  # K = 1, each sample its window's own future (distance 0)
    idx, mask = np.array([[0, 1], [1, 2], [2, 0]]), np.array([[True, True], [True, False], [True, True]])
    ade, fde = M.mm_errors(pred, futures, idx, mask)
    want = _mm_loop(pred, futures, idx, mask)
    np.testing.assert_allclose(np.asarray(ade), want[0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(fde), want[1], rtol=1e-5, atol=1e-6)
    assert float(ade[1]) == 0.0 and float(fde[1]) == 0.0  # the only member is the sample itself
