"""The reparameterised draw of a diagonal Gaussian latent (a VAE's encoder output)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.batch import batch_rows


def reparameterise(mu: Float[ArrayLike, "..."], logvar: Float[ArrayLike, "..."], key: jax.Array | None) -> Float[Array, "..."]:
    """Returns `mu + exp(logvar / 2) * eps`, eps ~ N(0, I) (Kingma & Welling Eq. (10)); `mu` when `key` is None."""
    if key is None:
        return mu
    eps = batch_rows(lambda n: jax.random.normal(key, (n,) + mu.shape[1:]), mu.shape[0])
    return mu + jnp.exp(0.5 * logvar) * eps
