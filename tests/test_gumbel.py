"""Coefficient samplers of DivSamp (jaxmotion.gumbel): simplex rows, entropy ordering, the Gumbel-max property."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jaxtyping import TypeCheckError

from jaxmotion import gumbel

SAMPLERS = {
    "gumbel": gumbel.gumbel_softmax_coefficients,
    "uniform": gumbel.uniform_softmax_coefficients,
    "gaussian": gumbel.gaussian_softmax_coefficients,
}


@pytest.mark.parametrize("kind", sorted(SAMPLERS))
@pytest.mark.parametrize("k,m,tau", [(1, 1, 1.0), (50, 40, 1.0), (7, 3, 0.1), (1000, 40, 0.85), (5, 10, 10.0)])
def test_rows_are_non_negative_and_sum_to_one(kind, k, m, tau):
    w = np.asarray(SAMPLERS[kind](jax.random.key(0), k, m, tau=tau))
    assert w.shape == (k, m)
    assert np.all(np.isfinite(w)) and np.all(w >= 0)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)


@pytest.mark.parametrize("tau", [0.5, 1.0, 2.0])
def test_gumbel_rows_have_lower_entropy_than_uniform_softmax_rows(tau):
    key = jax.random.key(1)
    h_g = float(jnp.mean(gumbel.row_entropy(gumbel.gumbel_softmax_coefficients(key, 2000, 40, tau=tau))))
    h_u = float(jnp.mean(gumbel.row_entropy(gumbel.uniform_softmax_coefficients(key, 2000, 40, tau=tau))))
    # U(0, 1) noise has std 0.29 against the Gumbel's 1.28: softmax of it stays near uniform (entropy
    # close to log 40 = 3.69), Gumbel-Softmax rows concentrate on a few bases.
    assert h_g < h_u - 0.3
    assert h_u < np.log(40) + 1e-5


def test_gumbel_max_recovers_pi():
    # Gumbel-max trick: argmax_m (log pi_m + g_m) ~ Categorical(pi); softmax at tau -> 0 becomes that one-hot.
    pi = jnp.array([0.6, 0.3, 0.1])
    w = np.asarray(gumbel.gumbel_softmax_coefficients(jax.random.key(2), 20000, 3, pi=pi, tau=1e-3))
    assert np.mean(w.max(axis=1) > 0.99) > 0.99  # near one-hot, but for near-ties of the noisy logits
    freq = np.bincount(w.argmax(axis=1), minlength=3) / len(w)
    np.testing.assert_allclose(freq, np.asarray(pi), atol=0.015)


def test_uniform_pi_equals_default_and_logits_equal_log_pi():
    key = jax.random.key(3)
    a = gumbel.gumbel_softmax_coefficients(key, 6, 5)
    b = gumbel.gumbel_softmax_coefficients(key, 6, 5, pi=jnp.full((5,), 0.2))
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-6)
    pi = jnp.array([0.5, 0.2, 0.1, 0.1, 0.1])
    c = gumbel.gumbel_softmax_coefficients(key, 6, 5, pi=pi)
    d = gumbel.gumbel_softmax_coefficients(key, 6, 5, logits=jnp.log(pi) + 3.0)  # a shift changes nothing
    np.testing.assert_allclose(np.asarray(c), np.asarray(d), atol=1e-6)


def test_gradient_reaches_learned_logits():
    f = lambda lg: gumbel.gumbel_softmax_coefficients(jax.random.key(4), 8, 4, logits=lg)[:, 0].sum()
    g = jax.grad(f)(jnp.zeros(4))
    assert np.all(np.isfinite(np.asarray(g))) and float(jnp.abs(g).sum()) > 0


def test_bad_arguments_are_named():
    key = jax.random.key(0)
    with pytest.raises(ValueError, match="tau"):
        gumbel.gumbel_softmax_coefficients(key, 3, 4, tau=0.0)
    with pytest.raises(ValueError, match="not both"):
        gumbel.gumbel_softmax_coefficients(key, 3, 4, pi=jnp.ones(4) / 4, logits=jnp.zeros(4))
    with pytest.raises(ValueError, match="m = 4"):
        gumbel.gumbel_softmax_coefficients(key, 3, 4, pi=jnp.ones(5) / 5)
    with pytest.raises(ValueError, match="k"):
        gumbel.uniform_softmax_coefficients(key, 0, 4)
    # `kind` is a Literal: the test suite's jaxtyping hook rejects it first (TypeCheckError naming
    # the parameter); without the hook, the function's own check raises the ValueError.
    with pytest.raises((ValueError, TypeCheckError), match="kind"):
        gumbel.sample_coefficients(key, 3, 4, kind="dirichlet")
    with pytest.raises(ValueError, match="learned pi"):
        gumbel.sample_coefficients(key, 3, 4, kind="uniform", logits=jnp.zeros(4))
