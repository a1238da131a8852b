"""The orthonormal DCT-II as a fixed matrix, applied along time (axis -2 of `(..., T, D)`), and DCT node features.

DCT node features (DivSamp Sec. 3.1, GSPS): a window as a graph of its J joints, each joint's
features the first `n_dct` DCT coefficients of its x, y and z trajectories; the history is
padded to the window's length by repeating its last pose.
"""

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


def pad_history(x: Float[ArrayLike, "b t_his d"], t_pred: int) -> Float[Array, "b t d"]:
    """Returns the history followed by `t_pred` copies of its last pose (DivSamp Sec. 3.1)."""
    return jnp.concatenate([x, jnp.repeat(x[:, -1:], t_pred, axis=1)], axis=1)


def to_nodes(seq: Float[ArrayLike, "b t d"], n_dct: int) -> Float[Array, "b j c"]:
    """Returns `(b, J, 3 * n_dct)`: the first `n_dct` DCT coefficients of each coordinate, grouped by joint."""
    c = dct(seq, n_dct)  # (b, n_dct, D)
    b, n, d = c.shape
    # Per joint [x_0..x_{n-1}, y_0.., z_0..], the release's `view(b, -1, 3 * dct_n)` layout.
    return c.reshape(b, n, d // 3, 3).transpose(0, 2, 3, 1).reshape(b, d // 3, 3 * n)


def from_nodes(nodes: Float[ArrayLike, "b j c"], n_frames: int) -> Float[Array, "b t d"]:
    """Returns the `(b, n_frames, D)` frames whose DCT coefficients are `nodes` (the inverse of `to_nodes`)."""
    b, j, c = nodes.shape
    n = c // 3
    coeffs = nodes.reshape(b, j, 3, n).transpose(0, 3, 1, 2).reshape(b, n, j * 3)
    return idct(coeffs, n_frames)


def condition_nodes(x: Float[ArrayLike, "b t_his d"], t_pred: int, n_dct: int) -> Float[Array, "b j c"]:
    """Returns the DCT node features of the history padded to `t_his + t_pred` frames: what DivSamp's and GSPS's networks condition on."""
    return to_nodes(pad_history(x, t_pred), n_dct)
