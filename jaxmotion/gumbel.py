"""Random coefficient matrices W (K x M) whose rows lie on the probability simplex (DivSamp Sec. 3.3).

DivSamp (Dang et al., ACM MM 2022) draws K points of an auxiliary space as convex combinations
`P = W B` of M learned basis vectors B; every row of W is a Gumbel-Softmax sample (Jang et al.,
ICLR 2017, Eq. (1)): `w_km = softmax_m((log pi_m + g_km) / tau)`, `g = -log(-log U)`, U ~ U(0, 1).
The paper's ablation (Table 5) replaces the Gumbel noise by U(0, 1) ("Uniform-Softmax") or
N(0, 1) ("Gaussian-Softmax") noise. Every function here is pure: a key in, an array out.
"""

from __future__ import annotations

from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

CoefficientKind = Literal["gumbel", "uniform", "gaussian"]
COEFFICIENT_KINDS = ("gumbel", "uniform", "gaussian")

# The released code draws U ~ U(0, 1) and adds 1e-20 inside both logarithms; we draw U from
# (tiny, 1) instead, which keeps -log(-log U) finite without changing the distribution measurably.
_TINY = float(jnp.finfo(jnp.float32).tiny)


def _check(fn: str, k: int, m: int, tau: float):
    if int(k) < 1:
        raise ValueError(f"{fn}: k (number of samples) must be >= 1, got {k}")
    if int(m) < 1:
        raise ValueError(f"{fn}: m (number of basis vectors) must be >= 1, got {m}")
    if not isinstance(tau, jax.core.Tracer) and not float(tau) > 0:
        raise ValueError(f"{fn}: tau (temperature) must be > 0, got {tau}")


def gumbel_noise(key: jax.Array, shape: tuple[int, ...]) -> Float[Array, "..."]:
    """Returns standard Gumbel samples `-log(-log U)`, U ~ U(0, 1)."""
    u = jax.random.uniform(key, shape, jnp.float32, minval=_TINY, maxval=1.0)
    return -jnp.log(-jnp.log(u))


def gumbel_softmax_coefficients(
    key: jax.Array,
    k: int,
    m: int,
    *,
    pi: Float[Array, "... m"] | None = None,
    tau: float = 1.0,
    logits: Float[Array, "... m"] | None = None,
) -> Float[Array, "k m"]:
    """Returns W (k, m), rows `softmax((log pi + g) / tau)`, g ~ Gumbel(0, 1) (DivSamp Eq. (9)-(10)).

    `pi` are category probabilities (default uniform, `1/m`, the paper's choice); pass
    unnormalised `logits` instead for a learned pi (one of the two, not both). Either may be
    `(m,)` (shared by every row) or `(k, m)` (one per row). Rows are non-negative and sum to 1.
    """
    _check("gumbel_softmax_coefficients", k, m, tau)
    if pi is not None and logits is not None:
        raise ValueError("gumbel_softmax_coefficients: pass `pi` or `logits`, not both")
    if logits is None:
        # A uniform pi contributes the same constant to every logit: softmax ignores it.
        logits = jnp.zeros((m,), jnp.float32) if pi is None else jnp.log(jnp.asarray(pi, jnp.float32))
    if logits.shape[-1] != m:
        raise ValueError(f"gumbel_softmax_coefficients: pi/logits must end in m = {m}, got shape {logits.shape}")
    g = gumbel_noise(key, (k, m))
    return jax.nn.softmax((logits + g) / tau, axis=-1)


def uniform_softmax_coefficients(key: jax.Array, k: int, m: int, *, tau: float = 1.0) -> Float[Array, "k m"]:
    """Returns W (k, m), rows `softmax(u / tau)`, u ~ U(0, 1): the "Uniform-Softmax" ablation (DivSamp Table 5)."""
    _check("uniform_softmax_coefficients", k, m, tau)
    return jax.nn.softmax(jax.random.uniform(key, (k, m), jnp.float32) / tau, axis=-1)


def gaussian_softmax_coefficients(key: jax.Array, k: int, m: int, *, tau: float = 1.0) -> Float[Array, "k m"]:
    """Returns W (k, m), rows `softmax(n / tau)`, n ~ N(0, 1): the "Gaussian-Softmax" ablation (DivSamp Table 5)."""
    _check("gaussian_softmax_coefficients", k, m, tau)
    return jax.nn.softmax(jax.random.normal(key, (k, m), jnp.float32) / tau, axis=-1)


def sample_coefficients(
    key: jax.Array,
    k: int,
    m: int,
    *,
    kind: CoefficientKind = "gumbel",
    tau: float = 1.0,
    logits: Float[Array, "... m"] | None = None,
) -> Float[Array, "k m"]:
    """Returns W (k, m) from the sampler named by `kind`; `logits` (a learned pi) only for "gumbel"."""
    if kind == "gumbel":
        return gumbel_softmax_coefficients(key, k, m, tau=tau, logits=logits)
    if logits is not None:
        raise ValueError(f"sample_coefficients: a learned pi (logits) needs kind='gumbel', got kind={kind!r}")
    if kind == "uniform":
        return uniform_softmax_coefficients(key, k, m, tau=tau)
    if kind == "gaussian":
        return gaussian_softmax_coefficients(key, k, m, tau=tau)
    raise ValueError(f"sample_coefficients: kind must be one of {COEFFICIENT_KINDS}, got {kind!r}")


def row_entropy(w: Float[Array, "... m"]) -> Float[Array, "..."]:
    """Returns the Shannon entropy (nats) of each row of a row-stochastic matrix."""
    return -jnp.sum(jnp.where(w > 0, w * jnp.log(jnp.where(w > 0, w, 1.0)), 0.0), axis=-1)
