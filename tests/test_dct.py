import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmotion.dct import dct, dct_matrix, idct


@given(st.integers(1, 80))
@settings(max_examples=25, deadline=None)
def test_dct_matrix_is_orthonormal(n):
    c = np.asarray(dct_matrix(n), np.float64)
    np.testing.assert_allclose(c @ c.T, np.eye(n), atol=1e-5)
    np.testing.assert_allclose(c.T @ c, np.eye(n), atol=1e-5)


def test_dct_matches_reference_formula():
    # DCT-II, orthonormal: X_k = sqrt(2/N) c_k sum_t x_t cos(pi (2t+1) k / 2N), c_0 = 1/sqrt(2).
    x = np.array([1.0, 2.0, 0.0, -1.0])
    n = len(x)
    ref = [np.sqrt(2 / n) * (1 / np.sqrt(2) if k == 0 else 1) * sum(x[t] * np.cos(np.pi * (2 * t + 1) * k / (2 * n)) for t in range(n)) for k in range(n)]
    got = np.asarray(dct(jnp.asarray(x)[:, None]))[:, 0]
    np.testing.assert_allclose(got, ref, atol=1e-6)
    assert got[0] == pytest.approx(x.sum() / 2)  # DC term: sum / sqrt(N)


@given(st.integers(2, 60), st.integers(1, 5), st.integers(0, 2**31 - 1))
@settings(max_examples=25, deadline=None)
@pytest.mark.slow
def test_full_dct_reconstructs_perfectly(t, d, seed):
    x = np.random.default_rng(seed).normal(size=(3, t, d)).astype(np.float32)
    np.testing.assert_allclose(np.asarray(idct(dct(jnp.asarray(x)), t)), x, atol=1e-4)


def test_truncation_is_a_projection_and_keeps_smooth_signals():
    t = 40
    x = np.random.default_rng(0).normal(size=(t, 3)).astype(np.float32)
    once = idct(dct(jnp.asarray(x), 10), t)
    twice = idct(dct(once, 10), t)
    np.testing.assert_allclose(np.asarray(twice), np.asarray(once), atol=1e-5)
    # A signal made of the first 10 basis functions survives truncation to 10 coefficients.
    coeffs = np.random.default_rng(1).normal(size=(10, 3)).astype(np.float32)
    smooth = idct(jnp.asarray(coeffs), t)
    np.testing.assert_allclose(np.asarray(dct(smooth, 10)), coeffs, atol=1e-5)


def test_bad_sizes_raise():
    with pytest.raises(ValueError, match="n_dct"):
        dct_matrix(5, 6)
    with pytest.raises(ValueError, match="n must be"):
        dct_matrix(0)
