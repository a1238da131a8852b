"""The orthonormal DCT-II matrix (as jaxmotion/dct.py), applied along time (axis -2 of `(..., T, D)`)."""

from __future__ import annotations

import functools

import numpy as np
import torch


@functools.lru_cache(maxsize=64)
def _matrix(n: int) -> torch.Tensor:
    k = np.arange(n)[:, None]
    t = np.arange(n)[None, :]
    m = np.sqrt(2.0 / n) * np.cos(np.pi * (2 * t + 1) * k / (2 * n))
    m[0] /= np.sqrt(2.0)
    return torch.tensor(m, dtype=torch.float32)


def dct_matrix(n: int, n_dct: int | None = None) -> torch.Tensor:
    """Returns the `(n_dct, n)` orthonormal DCT-II matrix (its first `n_dct` rows)."""
    return _matrix(n)[: n if n_dct is None else n_dct]


def dct(x: torch.Tensor, n_dct: int | None = None) -> torch.Tensor:
    """Returns the first `n_dct` DCT-II coefficients of `x (..., t, d)` along time."""
    return dct_matrix(x.shape[-2], n_dct) @ x


def idct(c: torch.Tensor, n: int) -> torch.Tensor:
    """Returns the `n`-frame signal whose first DCT-II coefficients are `c (..., c, d)`."""
    return dct_matrix(n, c.shape[-2]).T @ c
