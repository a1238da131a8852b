"""Pose augmentations: left/right mirroring and rotation about the vertical axis.

Pure `jax.numpy` functions over joint positions `(..., J, 3)` (any leading axes, e.g.
`(batch, time, J, 3)`), so they can run inside a jitted train step. For frame vectors
`(..., D)` with the root dropped (`windows.to_frames`) use the `*_frames` variants.

Which axis is up depends on the data: BVH files (Bandai-Namco-2, CMU) are Y-up (`up_axis=1`, the
default), Human3.6M and HumanEva-I world coordinates are Z-up (`up_axis=2`). Every loader in
`datasets.py` records it in `MotionDataset.info["up_axis"]`, and its mirror pairs in
`info["left_right_pairs"]`.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import jax.numpy as jnp
from jax import Array
from jax.typing import ArrayLike


def mirror(positions: ArrayLike, left_right_pairs: Sequence[tuple[int, int]], *, axis: int = 0) -> Array:
    """Returns the mirror image `(..., J, 3)`: coordinate `axis` negated, left/right joints swapped.

    Reflecting across any vertical plane gives a plausible body, so `axis` may be any horizontal
    axis (x for both Y-up and Z-up data). Mirroring twice is the identity.
    """
    x = jnp.asarray(positions)
    perm = list(range(x.shape[-2]))
    for left, right in left_right_pairs:
        perm[left], perm[right] = right, left
    sign = jnp.ones(3, x.dtype).at[axis].set(-1)
    return x[..., jnp.array(perm), :] * sign


def mirror_frames(frames: ArrayLike, left_right_pairs: Sequence[tuple[int, int]], *, axis: int = 0) -> Array:
    """Returns mirrored frame vectors `(..., D)`, `D = (J-1)*3`, the root (joint 0) dropped.

    `left_right_pairs` index the skeleton's joints (root = 0), as in `info["left_right_pairs"]`.
    """
    x = jnp.asarray(frames)
    pairs = [(left - 1, right - 1) for left, right in left_right_pairs]
    if any(min(p) < 0 for p in pairs):
        raise ValueError("mirror_frames: the root (joint 0) cannot be in a left/right pair")
    return mirror(_points(x), pairs, axis=axis).reshape(x.shape)


def yaw_matrix(angle: ArrayLike, up_axis: int = 1) -> Array:
    """Returns `(..., 3, 3)` right-handed rotations by `angle` (radians) about axis `up_axis`."""
    angle = jnp.asarray(angle)
    c, s = jnp.cos(angle), jnp.sin(angle)
    # Rotation about axis a maps axis (a+1) towards (a+2): x->y about z, y->z about x, z->x about y.
    i, j = (up_axis + 1) % 3, (up_axis + 2) % 3
    r = jnp.zeros(angle.shape + (3, 3), c.dtype)
    r = r.at[..., up_axis, up_axis].set(1.0)
    r = r.at[..., i, i].set(c).at[..., j, j].set(c)
    return r.at[..., i, j].set(-s).at[..., j, i].set(s)


def rotate_yaw(positions: ArrayLike, angle: ArrayLike, *, up_axis: int = 1) -> Array:
    """Returns `positions (..., J, 3)` rotated by `angle` radians about the vertical axis.

    The rotation is about the line through the origin; for root-relative poses that is the
    root's vertical. `angle` is a scalar or has the *leading* axes of `positions` (e.g. `(B,)`
    for `(B, T, J, 3)`: one angle per sequence); it is broadcast from the left.
    """
    x = jnp.asarray(positions)
    angle = jnp.asarray(angle)
    extra = x.ndim - 2 - angle.ndim
    if extra < 0:
        raise ValueError(f"rotate_yaw: angle shape {angle.shape} has more axes than positions {x.shape[:-2]}")
    rot = yaw_matrix(angle.reshape(angle.shape + (1,) * extra), up_axis).astype(x.dtype)
    return jnp.einsum("...ij,...kj->...ki", rot, x)


def rotate_yaw_frames(frames: ArrayLike, angle: ArrayLike, *, up_axis: int = 1) -> Array:
    """Returns frame vectors `(..., D)` rotated about the vertical axis (see `rotate_yaw`)."""
    x = jnp.asarray(frames)
    return rotate_yaw(_points(x), angle, up_axis=up_axis).reshape(x.shape)


def _points(frames: Array) -> Array:
    if frames.shape[-1] % 3:
        raise ValueError(f"frame vectors must have a multiple of 3 numbers, got shape {frames.shape}")
    return frames.reshape(frames.shape[:-1] + (-1, 3))


# Each pattern names a left joint; its right partner is the same name with the side swapped.
_SIDE_PATTERNS = (
    (re.compile(r"^(.*)_L$"), r"\1_R"),  # Bandai: UpperArm_L
    (re.compile(r"^(.*)\.L$"), r"\1.R"),  # Blender
    (re.compile(r"^Left(.*)$"), r"Right\1"),  # CMU, Mixamo: LeftUpLeg
    (re.compile(r"^left_(.*)$"), r"right_\1"),  # SMPL: left_hip
    (re.compile(r"^L([A-Z].*)$"), r"R\1"),  # CMU, H36M: LHipJoint, LShoulder
    (re.compile(r"^l([a-z].*)$"), r"r\1"),  # HumanEva: lsho
)


def left_right_pairs(names: Sequence[str]) -> list[tuple[int, int]]:
    """Returns `(left, right)` joint index pairs found by name (`X_L`/`X_R`, `LeftX`/`RightX`, ...).

    A joint is paired only if its exact counterpart exists, so names like `LowerBack` stay unpaired.
    """
    index = {n: i for i, n in enumerate(names)}
    pairs = []
    for i, n in enumerate(names):
        for pattern, repl in _SIDE_PATTERNS:
            if pattern.match(n):
                j = index.get(pattern.sub(repl, n))
                if j is not None and j != i:
                    pairs.append((i, j))
                    break
    return pairs
