"""The orthonormal DCT-II as a fixed matrix, applied along time (axis -2 of `(..., T, D)`)."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


@functools.lru_cache(maxsize=64)
def _dct_matrix_np(n: int) -> np.ndarray:
    k = np.arange(n)[:, None]
    t = np.arange(n)[None, :]
    m = np.sqrt(2.0 / n) * np.cos(np.pi * (2 * t + 1) * k / (2 * n))
    m[0] /= np.sqrt(2.0)
    m.setflags(write=False)
    return m


def dct_matrix(n: int, n_dct: int | None = None) -> Float[Array, "c n"]:
    """Returns the `(n_dct, n)` orthonormal DCT-II matrix (first `n_dct` rows; all when None).

    Row k is `sqrt(2/n) c_k cos(pi (2t+1) k / 2n)` with `c_0 = 1/sqrt(2)`, `c_k = 1` otherwise, so
    the full matrix `C` satisfies `C @ C.T = I` and the inverse transform is `C.T`.
    """
    if n < 1:
        raise ValueError(f"dct_matrix: n must be >= 1, got {n}")
    n_dct = n if n_dct is None else n_dct
    if not 1 <= n_dct <= n:
        raise ValueError(f"dct_matrix: n_dct must be in [1, {n}], got {n_dct}")
    return jnp.asarray(_dct_matrix_np(n)[:n_dct], dtype=jnp.float32)


def dct(x: Float[ArrayLike, "... t d"], n_dct: int | None = None) -> Float[Array, "... c d"]:
    """Returns the first `n_dct` DCT-II coefficients of `x` along time (axis -2)."""
    return jnp.einsum("ct,...td->...cd", dct_matrix(x.shape[-2], n_dct), x)


def idct(c: Float[ArrayLike, "... c d"], n: int) -> Float[Array, "... t d"]:
    """Returns the `n`-frame signal whose first DCT-II coefficients are `c` (the rest zero)."""
    return jnp.einsum("ct,...cd->...td", dct_matrix(n, c.shape[-2]), c)
