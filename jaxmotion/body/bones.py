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


def with_bone_lengths(
    frames: Float[ArrayLike, "*s d"], lengths: Float[ArrayLike, "*t b"], parents: tuple[int, ...], *,
    borrow_direction: bool = False, span_zero_bones: bool = False,
) -> Float[Array, "*o d"]:
    """Returns `frames` rebuilt parent to child from the root at the origin, every bone keeping its direction in
    `frames` and taking its length from `lengths` (`(..., J - 1)`, bone i ends at joint i + 1), broadcast over leading axes.

    Two skeletons may split a limb differently (one puts the clavicle or the neck at its parent's joint, with
    zero length, the other gives it a length). `borrow_direction`: a bone of zero length in `frames` (no
    direction) takes the direction of its first child bone, instead of staying at zero length.
    `span_zero_bones`: a bone whose parent bone has zero length in `lengths` points from the nearest joint
    above it that a bone of non-zero length ends at (or the root), so that it spans the bones it replaces.
    """
    fp = frame_parents(parents)
    frames, lengths = jnp.asarray(frames), jnp.asarray(lengths, jnp.result_type(frames.dtype, jnp.float32))
    if lengths.shape[-1] != len(fp):
        raise ValueError(f"with_bone_lengths: {lengths.shape[-1]} bone lengths for a skeleton of {len(parents)} joints ({len(fp)} bones)")
    bones = bone_vectors(frames, parents)
    unit = lambda v: v / jnp.maximum(jnp.linalg.norm(v, axis=-1, keepdims=True), 1e-12)  # noqa: E731
    directions = [unit(bones[..., j, :]) for j in range(len(fp))]
    if borrow_direction:
        norms = jnp.linalg.norm(bones, axis=-1, keepdims=True)
        for j in reversed(range(len(fp))):  # children come after their parents: theirs are final when j is reached
            child = next((c for c, p in enumerate(fp) if p == j), None)
            if child is not None:
                directions[j] = jnp.where(norms[..., j, :] > 1e-6, directions[j], directions[child])
    if span_zero_bones:
        joints = frames.reshape(frames.shape[:-1] + (-1, 3))
        at = lambda a: joints[..., a, :] if a >= 0 else jnp.zeros_like(joints[..., 0, :])  # noqa: E731  (-1: the root)
        for j in range(len(fp)):
            chain, a = [], fp[j]
            while a >= 0:  # the joints above j, nearest first; the root (-1) last
                chain.append(a)
                a = fp[a]
            d = unit(joints[..., j, :] - at(-1))
            for a in reversed(chain):  # the nearest ancestor whose own bone has a length wins
                d = jnp.where(lengths[..., a, None] > 1e-6, unit(joints[..., j, :] - at(a)), d)
            directions[j] = d
    shape = jnp.broadcast_shapes(bones.shape[:-2], lengths.shape[:-1]) + (3,)
    out: list = []
    for j, p in enumerate(fp):
        base = out[p] if p >= 0 else jnp.zeros(shape, frames.dtype)
        out.append(jnp.broadcast_to(base + lengths[..., j, None] * directions[j], shape))
    return jnp.stack(out, axis=-2).reshape(shape[:-1] + (-1,)).astype(frames.dtype)


def motion_transfer(
    source: Float[Array, "*s d"], target: Float[Array, "*t d"], parents: tuple[int, ...]
) -> Float[Array, "*o d"]:
    """Returns `source`'s motion on `target`'s skeleton (MotionMap appendix A), broadcast over leading axes.

    Every link keeps the direction it has in `source` (its spherical angles) and takes the length it
    has in `target`; joints are rebuilt parent to child from the root at the origin. `parents` is
    the skeleton's (root first, dropped from the frame vectors).
    """
    frame_parents(parents)  # the parents' order is checked before any bone is measured
    return with_bone_lengths(source, bone_lengths(target, parents), parents)
