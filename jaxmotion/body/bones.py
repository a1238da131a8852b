"""The skeleton's bones of root-relative, root-dropped frame vectors ([protocol §1][representation]), and motion transfer.

A frame vector holds the J - 1 non-root joints (the root sits at the origin), so a bone from the
root is its child's position. DivSamp's and GSPS's limb losses compare bone lengths; MotionMap's
multimodal ground truth moves a motion onto another skeleton by keeping each bone's direction and
taking the other skeleton's length (`motion_transfer`, MotionMap appendix A).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Float


def bone_matrix(parents: tuple[int, ...]) -> np.ndarray:
    """Returns the `(D, D)` matrix `B` (D = 3 (J - 1)) with `frames @ B` = the bone vectors `p_i - p_parent(i)`, i = 1..J-1.

    `frames` are root-relative and root-dropped ([protocol §1][representation]: the root sits at the origin, so a
    bone from the root is its child's position). `B` holds only 0 and +-1, so the product is exactly
    the subtraction. It replaces two gathers over the joint axis, whose gradients are scatter-adds:
    in GSPS's generator step (1,600 futures) those took ~5% of the step.
    """
    parents = tuple(int(p) for p in parents)
    bad = [i for i in range(1, len(parents)) if not 0 <= parents[i] < len(parents) or parents[i] == i]
    if bad:
        raise ValueError(f"bone_matrix: joint {bad[0]}'s parent is {parents[bad[0]]}; every joint but the root (joint 0) "
                         f"needs another joint of the {len(parents)} as its parent")
    m = np.zeros((len(parents) - 1,) * 2, np.float32)  # m[i - 1, k - 1]: joint k's weight in bone i
    for i in range(1, len(parents)):
        m[i - 1, i - 1] = 1.0
        if parents[i] > 0:
            m[i - 1, parents[i] - 1] = -1.0
    return np.kron(m.T, np.eye(3, dtype=np.float32))


def bone_vectors(frames: Float[ArrayLike, "... d"], parents: tuple[int, ...]) -> Float[Array, "... b 3"]:
    """Returns the `(..., J - 1, 3)` bone vectors `p_i - p_parent(i)` of root-relative, root-dropped frame vectors."""
    frames = jnp.asarray(frames)
    if frames.shape[-1] != 3 * (len(parents) - 1):
        raise ValueError(f"bone_vectors: frames of {frames.shape[-1]} values do not fit a skeleton of {len(parents)} joints "
                         f"(root-dropped frames have 3 (J - 1) = {3 * (len(parents) - 1)})")
    # HIGHEST: exact on every backend (a GPU's or TPU's default float32 product rounds its operands).
    v = jnp.matmul(frames, jnp.asarray(bone_matrix(parents)), precision=lax.Precision.HIGHEST)
    return v.reshape(v.shape[:-1] + (-1, 3))


def bone_lengths(frames: Float[ArrayLike, "... d"], parents: tuple[int, ...]) -> Float[Array, "... b"]:
    """Returns the `J - 1` bone lengths of root-relative, root-dropped frame vectors ([protocol §1][representation])."""
    return jnp.linalg.norm(bone_vectors(frames, parents), axis=-1)


def frame_parents(parents: tuple[int, ...]) -> tuple[int, ...]:
    """Returns the parent of every frame joint (skeleton joint j + 1), -1 where the parent is the dropped root."""
    parents = tuple(int(p) for p in parents)
    if parents[0] != -1 or any(not 0 <= p < j for j, p in enumerate(parents) if j):
        raise ValueError(f"motion transfer needs joint 0 as the root and every parent before its child, got parents {parents}")
    return tuple(p - 1 for p in parents[1:])


def motion_transfer(
    source: Float[Array, "*s d"], target: Float[Array, "*t d"], parents: tuple[int, ...]
) -> Float[Array, "*o d"]:
    """Returns `source`'s motion on `target`'s skeleton (MotionMap appendix A), broadcast over leading axes.

    Every link keeps the direction it has in `source` (its spherical angles) and takes the length it
    has in `target`; joints are rebuilt parent to child from the root at the origin. `parents` is
    the skeleton's (root first, dropped from the frame vectors).
    """
    fp = frame_parents(parents)
    bones_src, bones_tgt = bone_vectors(source, parents), bone_vectors(target, parents)
    shape = jnp.broadcast_shapes(bones_src.shape[:-2], bones_tgt.shape[:-2]) + (3,)
    out: list = []
    for j, p in enumerate(fp):
        v_src, v_tgt = bones_src[..., j, :], bones_tgt[..., j, :]
        norm = jnp.linalg.norm(v_src, axis=-1, keepdims=True)
        direction = v_src / jnp.maximum(norm, 1e-12)
        length = jnp.linalg.norm(v_tgt, axis=-1, keepdims=True)
        base = out[p] if p >= 0 else jnp.zeros(shape, source.dtype)
        out.append(jnp.broadcast_to(base + length * direction, shape))
    return jnp.stack(out, axis=-2).reshape(shape[:-1] + (-1,))
