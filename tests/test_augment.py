"""Mirroring and yaw rotation: involution, rigidity, known values, jit, frame-vector variants."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.data import datasets
from jaxmotion.data.augment import (
    left_right_pairs,
    mirror,
    mirror_frames,
    rotate_yaw,
    rotate_yaw_frames,
    yaw_matrix,
)
from jaxmotion.data.windows import to_frames
from jaxmotion.formats.bvh import euler_matrices

PARENTS = datasets.HUMANEVA_PARENTS
PAIRS = left_right_pairs(datasets.HUMANEVA_JOINT_NAMES)


def motion(shape=(2, 4, 15, 3), seed=0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=shape).astype(np.float32)


def bone_lengths(x) -> np.ndarray:
    x = np.asarray(x)
    return np.stack([np.linalg.norm(x[..., j, :] - x[..., p, :], axis=-1) for j, p in enumerate(PARENTS) if p >= 0])


def test_mirror_twice_is_identity_and_swaps_sides():
    x = motion()
    m = mirror(x, PAIRS)
    np.testing.assert_allclose(mirror(m, PAIRS), x, atol=0)
    lsho, rsho = datasets.HUMANEVA_JOINT_NAMES.index("lsho"), datasets.HUMANEVA_JOINT_NAMES.index("rsho")
    np.testing.assert_allclose(m[..., lsho, :], x[..., rsho, :] * np.array([-1, 1, 1]))
    np.testing.assert_allclose(m[..., 0, :], x[..., 0, :] * np.array([-1, 1, 1]))  # unpaired: reflected only
    # A symmetric skeleton keeps its bone lengths, with left and right bones exchanged.
    np.testing.assert_allclose(np.sort(bone_lengths(m), 0), np.sort(bone_lengths(x), 0), rtol=1e-6)


def test_mirror_axis_and_jit():
    x = motion()
    m = jax.jit(lambda v: mirror(v, PAIRS, axis=2))(x)
    np.testing.assert_allclose(m[..., 0, :], x[..., 0, :] * np.array([1, 1, -1]))


def test_yaw_matrix_matches_bvh_euler_convention():
    for up, axis in enumerate("XYZ"):
        np.testing.assert_allclose(yaw_matrix(0.7, up), euler_matrices(np.array([np.rad2deg(0.7)]), axis), atol=1e-6)
    # Right-handed: a quarter turn about y takes x to -z; about z it takes x to y.
    np.testing.assert_allclose(rotate_yaw(jnp.array([[1.0, 0, 0]]), np.pi / 2), [[0, 0, -1]], atol=1e-6)
    np.testing.assert_allclose(rotate_yaw(jnp.array([[1.0, 0, 0]]), np.pi / 2, up_axis=2), [[0, 1, 0]], atol=1e-6)


@pytest.mark.parametrize("up_axis", [1, 2])
def test_rotate_yaw_is_rigid_and_keeps_height(up_axis):
    x = motion()
    r = rotate_yaw(x, 1.234, up_axis=up_axis)
    np.testing.assert_allclose(bone_lengths(r), bone_lengths(x), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(r[..., up_axis], x[..., up_axis], atol=1e-6)
    np.testing.assert_allclose(rotate_yaw(x, 2 * np.pi, up_axis=up_axis), x, atol=1e-5)
    np.testing.assert_allclose(rotate_yaw(r, -1.234, up_axis=up_axis), x, atol=1e-5)


def test_rotate_yaw_one_angle_per_sequence_under_jit():
    x = motion((3, 4, 15, 3))
    angles = jnp.array([0.1, -2.0, 3.0])
    batched = jax.jit(rotate_yaw)(x, angles)
    for b in range(3):
        np.testing.assert_allclose(batched[b], rotate_yaw(x[b], angles[b]), atol=1e-6)
    with pytest.raises(ValueError, match="angle"):
        rotate_yaw(x[0, 0], angles)


def test_frame_variants_agree_with_positions():
    x = motion((4, 15, 3))
    frames = to_frames(x)  # root-relative, root dropped: (4, 42)
    np.testing.assert_allclose(mirror_frames(frames, PAIRS), to_frames(np.asarray(mirror(x, PAIRS))), atol=1e-6)
    np.testing.assert_allclose(rotate_yaw_frames(frames, 0.5), to_frames(np.asarray(rotate_yaw(x, 0.5))), atol=1e-5)
    with pytest.raises(ValueError, match="root"):
        mirror_frames(frames, [(0, 1)])


def test_left_right_pairs_by_name():
    assert PAIRS == [(2, 5), (3, 6), (4, 7), (8, 11), (9, 12), (10, 13)]  # DLow's joints_left/right
    h36m = left_right_pairs(datasets.H36M_JOINT_NAMES)
    assert h36m == [(4, 1), (5, 2), (6, 3), (11, 14), (12, 15), (13, 16)]
    cmu = ["Hips", "LHipJoint", "LeftUpLeg", "RHipJoint", "RightUpLeg", "LowerBack", "LThumb", "RThumb"]
    assert left_right_pairs(cmu) == [(1, 3), (2, 4), (6, 7)]
    assert left_right_pairs(["Hips", "Hand_L", "Hand_R", "Spine"]) == [(1, 2)]
