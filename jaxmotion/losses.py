"""Loss terms shared by the methods: KL divergences, reconstruction and diversity terms.

Every function reduces over the axes it documents and nothing else, so a caller decides how to
average over a batch.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float


def kld_normal(mu: Float[Array, "... z"], logvar: Float[Array, "... z"]) -> Float[Array, "..."]:
    """Returns KL(N(mu, exp(logvar)) || N(0, I)) summed over the last axis (Kingma & Welling, App. B)."""
    return -0.5 * jnp.sum(1.0 + logvar - mu**2 - jnp.exp(logvar), axis=-1)


def kld_affine(a: Float[Array, "... z"], b: Float[Array, "... z"]) -> Float[Array, "..."]:
    """Returns KL(N(b, diag(a^2)) || N(0, I)) summed over the last axis (DLow's Q-network KL).

    `log(a^2 + 1e-10)` where DLow's release takes `log(a^2)`: the Q network's `a` is a linear layer's
    output and can cross zero, where the release's term is -inf and its gradient 2 / a unbounded. The
    floor changes the term by at most 1e-10 / a^2 per dimension (1e-6 nats at |a| = 0.01), bounds each
    dimension's term by 11.5 nats and its gradient by 1e5, and keeps every value finite.
    """
    var = a**2
    return -0.5 * jnp.sum(1.0 + jnp.log(var + 1e-10) - b**2 - var, axis=-1)


def robust_kld(kld: Float[Array, "..."]) -> Float[Array, "..."]:
    """Returns Psi(s) = sqrt(1 + s^2) - 1, MOJO's robust KLD (Eq. (1) of MOJO)."""
    # s^2 / (sqrt(1 + s^2) + 1) is the same number without float32 cancellation near s = 0.
    return kld**2 / (jnp.sqrt(1.0 + kld**2) + 1.0)


def pairwise_sq_dists(y: Float[Array, "k n"]) -> Float[Array, "k k"]:
    """Returns the `(k, k)` squared Euclidean distances between the rows of `y`."""
    sq = jnp.sum(y**2, axis=-1)
    d2 = sq[:, None] + sq[None, :] - 2.0 * y @ y.T
    return jnp.maximum(d2, 0.0)


def gram(a: Float[Array, "... p f"], b: Float[Array, "... q f"]) -> Float[Array, "... p q"]:
    """Returns every dot product `a_i . b_j`, in float32 on every backend."""
    # HIGHEST: float32 products even where the default would be TF32 / bfloat16 (GPU, TPU).
    return jnp.einsum("...pf,...qf->...pq", a, b, precision=lax.Precision.HIGHEST)


def pairwise_sq_distances(
    a: Float[Array, "... p f"], b: Float[Array, "... q f"], *, a_sq: Float[Array, "... p"] | None = None,
) -> Float[Array, "... p q"]:
    """Returns `||a_i - b_j||^2` for every pair, as `|a|^2 + |b|^2 - 2 a.b` (one product), clipped at 0.

    Rounding grows with the norms, not the distances: take both sides relative to a common point near
    them first (a true future, one of the samples). `a_sq`: `sum(a * a, -1)` where the caller has it.
    """
    a_sq = jnp.sum(a * a, axis=-1) if a_sq is None else a_sq
    b_sq = jnp.sum(b * b, axis=-1)
    return jnp.maximum(a_sq[..., :, None] + b_sq[..., None, :] - 2.0 * gram(a, b), 0.0)


def dlow_diversity(y: Float[Array, "k ..."], d_scale: float) -> Float[Array, ""]:
    """Returns mean_{i<j} exp(-||y_i - y_j||^2 / d_scale) over the K samples (DLow Eq. (9))."""
    k = y.shape[0]
    d2 = pairwise_sq_dists(y.reshape(k, -1))
    iu = jnp.triu_indices(k, 1)
    return jnp.mean(jnp.exp(-d2[iu] / d_scale))


def min_of_k_sq_error(y_k: Float[Array, "k t d"], y: Float[Array, "t d"]) -> Float[Array, ""]:
    """Returns min_k sum_{t,d} (y_k - y)^2: DLow's reconstruction term for one window."""
    return jnp.min(jnp.sum((y_k - y[None]) ** 2, axis=(-2, -1)))


def hinge_diversity(y: Float[Array, "k ..."], eta: float) -> Float[Array, ""]:
    """Returns mean_{i != j} max(0, eta - ||y_i - y_j||) over the K samples (DivSamp Eq. (13)).

    Unlike DLow's exp(-D^2) energy, pairs farther apart than `eta` cost nothing, so the loss only
    pushes apart samples that are still too close. Distances are over the flattened samples.
    """
    k = y.shape[0]
    d2 = pairwise_sq_dists(y.reshape(k, -1))
    iu = jnp.triu_indices(k, 1)
    # The floor keeps the gradient of sqrt finite for (near-)identical samples.
    d = jnp.sqrt(jnp.maximum(d2[iu], 1e-12))
    return jnp.mean(jnp.maximum(eta - d, 0.0))
