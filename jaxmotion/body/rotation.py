"""Rotations for body models: the continuous 6-D representation, axis-angle, and Kabsch alignment.

MOJO parameterises the global orientation by the 6-D representation of Zhou et al. (CVPR 2019):
the first two columns of the rotation matrix, re-orthonormalised by Gram-Schmidt. It has no
singularities, which matters when a solver starts from an arbitrary heading. Joint rotations are
axis-angle vectors (SMPL-X's convention), whose Jacobian at zero is well defined here.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)  # columns e1, e2 of the identity, flattened


def rot6d_to_matrix(x: Float[Array, "... 6"]) -> Float[Array, "... 3 3"]:
    """Returns rotation matrices from 6-D vectors `(a1, a2)` (Zhou et al. 2019, Eq. (15)).

    `a1 = x[..., :3]`, `a2 = x[..., 3:]` are the first and second columns before Gram-Schmidt.
    """
    a1, a2 = x[..., :3], x[..., 3:]
    b1 = a1 / jnp.sqrt(jnp.sum(a1**2, -1, keepdims=True) + 1e-12)
    a2 = a2 - jnp.sum(b1 * a2, -1, keepdims=True) * b1
    b2 = a2 / jnp.sqrt(jnp.sum(a2**2, -1, keepdims=True) + 1e-12)
    b3 = jnp.cross(b1, b2)
    return jnp.stack([b1, b2, b3], axis=-1)


def matrix_to_rot6d(r: Float[Array, "... 3 3"]) -> Float[Array, "... 6"]:
    """Returns the 6-D representation (first two columns) of rotation matrices."""
    return jnp.concatenate([r[..., :, 0], r[..., :, 1]], axis=-1)


def skew(v: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """Returns the cross-product matrices `[v]_x`."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = jnp.zeros_like(x)
    return jnp.stack([jnp.stack([o, -z, y], -1), jnp.stack([z, o, -x], -1), jnp.stack([-y, x, o], -1)], -2)


def axis_angle_to_matrix(v: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """Returns `exp([v]_x)` by Rodrigues' formula, with Taylor terms near 0 so gradients stay finite."""
    t2 = jnp.sum(v**2, -1)[..., None, None]
    small = t2 < 1e-8
    t2s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(t2s)
    a = jnp.where(small, 1.0 - t2 / 6.0, jnp.sin(t) / t)
    b = jnp.where(small, 0.5 - t2 / 24.0, (1.0 - jnp.cos(t)) / t2s)
    k = skew(v)
    return jnp.eye(3, dtype=v.dtype) + a * k + b * (k @ k)


def matrix_to_axis_angle(r: Float[Array, "... 3 3"]) -> Float[Array, "... 3"]:
    """Returns axis-angle vectors of rotation matrices (angles in [0, pi); used for initialisation)."""
    c = jnp.clip((jnp.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    t = jnp.arccos(c)
    w = jnp.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    s = jnp.sin(t)[..., None]
    scale = jnp.where(s > 1e-6, t[..., None] / (2.0 * jnp.where(s > 1e-6, s, 1.0)), 0.5)
    return w * scale


def kabsch(
    src: Float[Array, "m 3"], dst: Float[Array, "m 3"], weights: Float[Array, " m"]
) -> tuple[Float[Array, "3 3"], Float[Array, " 3"]]:
    """Returns `(R, t)` minimising `sum_i w_i ||R src_i + t - dst_i||^2` (Kabsch / Umeyama, no scale)."""
    w = weights / jnp.maximum(jnp.sum(weights), 1e-9)
    mu_s, mu_d = w @ src, w @ dst
    h = ((src - mu_s) * w[:, None]).T @ (dst - mu_d)
    u, _, vt = jnp.linalg.svd(h)
    d = jnp.sign(jnp.linalg.det(vt.T @ u.T))
    r = vt.T @ jnp.diag(jnp.array([1.0, 1.0, 1.0], h.dtype).at[2].set(d)) @ u.T
    return r, mu_d - r @ mu_s
