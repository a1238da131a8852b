"""BVH parsing and forward kinematics: hand-derived positions, real files, malformed files."""

from __future__ import annotations

import re
import tarfile
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.formats.bvh import euler_matrices, forward_kinematics, read_bvh

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
CMU_01_01 = SHARED_DATA / "cmu-bvh" / "01_01.bvh"
BANDAI_TARBALL = SHARED_DATA / "bandai-namco-2" / "bandai2_dev.tar.xz"

# A root with a position channel, a child whose rotation order is Y X Z, a leaf, and a sibling
# whose position channels replace its OFFSET (5 5 5).
CHAIN = """\
HIERARCHY
ROOT A
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT B
  {
    OFFSET 1 0 0
    CHANNELS 3 Yrotation Xrotation Zrotation
    JOINT C
    {
      OFFSET 0 2 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      End Site
      {
        OFFSET 0 0 3
      }
    }
  }
  JOINT D
  {
    OFFSET 5 5 5
    CHANNELS 3 Xposition Yposition Zposition
  }
}
MOTION
Frames: 2
Frame Time: 0.04
10 20 30 0 0 0   0 0 0    0 0 0   0 1 0
1 2 3 90 0 0     90 90 0  45 10 20   0 0 1
"""


def write(tmp_path: Path, text: str, name: str = "chain.bvh") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_chain_structure(tmp_path):
    bvh = read_bvh(write(tmp_path, CHAIN))
    assert bvh.names == ("A", "B", "C", "D")  # End Site is not a joint
    assert bvh.parents == (-1, 0, 1, 0)
    np.testing.assert_array_equal(bvh.offsets, [[0, 0, 0], [1, 0, 0], [0, 2, 0], [5, 5, 5]])
    assert bvh.channels[1] == ("Yrotation", "Xrotation", "Zrotation")
    assert bvh.motion.shape == (2, 15)
    assert bvh.channel_starts == (0, 6, 9, 12)
    assert bvh.fps == pytest.approx(25.0)


def test_chain_forward_kinematics_by_hand(tmp_path):
    bvh = read_bvh(write(tmp_path, CHAIN))
    pos = forward_kinematics(bvh)
    # Frame 0: no rotation; root at its position channels, D at its position channels (0 1 0).
    np.testing.assert_allclose(pos[0], [[10, 20, 30], [11, 20, 30], [11, 22, 30], [10, 21, 30]], atol=1e-12)
    # Frame 1: root Rz(90) maps x -> y. B = A + Rz(90) (1,0,0) = (1,3,3).
    # C = B + Rz(90) Ry(90) Rx(90) (0,2,0): Rx(90) -> (0,0,2), Ry(90) -> (2,0,0), Rz(90) -> (0,2,0).
    # (The wrong order Rz Rx Ry would give (0,0,2).) D = A + Rz(90) (0,0,1) = (1,2,4).
    np.testing.assert_allclose(pos[1], [[1, 2, 3], [1, 3, 3], [1, 5, 3], [1, 2, 4]], atol=1e-12)
    np.testing.assert_allclose(forward_kinematics(bvh, frames=[1]), pos[1:], atol=1e-12)
    np.testing.assert_allclose(forward_kinematics(bvh, frames=slice(0, 1)), pos[:1], atol=1e-12)


def test_euler_matrices_compose_in_channel_order():
    angles = np.array([30.0, -50.0, 70.0])
    rz, rx, ry = (euler_matrices(a[None], ax) for a, ax in zip(angles, "ZXY"))
    np.testing.assert_allclose(euler_matrices(angles, "ZXY"), rz @ rx @ ry, atol=1e-12)
    np.testing.assert_allclose(euler_matrices(np.array([90.0]), "Z") @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    r = euler_matrices(np.random.default_rng(0).uniform(-180, 180, (5, 3)), "XYZ")
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), (5, 3, 3)), atol=1e-12)


# --- malformed files ------------------------------------------------------------------------------

BROKEN = {
    "no_hierarchy": CHAIN.replace("HIERARCHY\n", ""),
    "no_motion": CHAIN.split("MOTION")[0],
    "missing_row": CHAIN.rsplit("1 2 3", 1)[0],
    "short_row": CHAIN.replace("0 0 1\n", "0 0\n"),
    "non_numeric": CHAIN.replace("45 10 20", "45 abc 20"),
    "nan": CHAIN.replace("45 10 20", "45 nan 20"),
    "bad_frames": CHAIN.replace("Frames: 2", "Frames: two"),
    "unbalanced": CHAIN.replace("MOTION", "{\nMOTION"),
    "unknown_channel": CHAIN.replace("Zrotation Yrotation Xrotation", "Zrotation Yrotation Wrotation"),
}


@pytest.mark.parametrize("kind", sorted(BROKEN))
def test_malformed_file_error_names_the_file(tmp_path, kind):
    path = write(tmp_path, BROKEN[kind], f"broken_{kind}.bvh")
    with pytest.raises(ValueError, match=re.escape(path.name)):
        read_bvh(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.bvh"):
        read_bvh(tmp_path / "nope.bvh")


# --- real files -------------------------------------------------------------------------------------


def bone_lengths(pos: np.ndarray, parents) -> np.ndarray:
    """Returns `(F, J-1)` distances from each non-root joint to its parent."""
    child = [j for j, p in enumerate(parents) if p >= 0]
    return np.linalg.norm(pos[:, child] - pos[:, [parents[j] for j in child]], axis=-1)


def test_cmu_01_01():
    if not CMU_01_01.is_file():
        pytest.skip(f"shared data not found at {CMU_01_01}")
    bvh = read_bvh(CMU_01_01)
    assert bvh.num_joints == 31
    assert bvh.names[:3] == ("Hips", "LHipJoint", "LeftUpLeg")
    assert bvh.fps == pytest.approx(120.0, rel=1e-4)
    assert bvh.motion.shape == (2752, 96)
    pos = forward_kinematics(bvh, frames=slice(0, None, 50)) * 0.056444
    lengths = bone_lengths(pos, bvh.parents)
    np.testing.assert_allclose(lengths, np.broadcast_to(lengths[0], lengths.shape), atol=1e-6)
    assert 0.3 < lengths.max() < 0.6  # the longest bones are thigh and shin
    hips_height = pos[:, 0, 1]
    assert np.all((0.6 < hips_height) & (hips_height < 1.5))  # Y-up; 01_01 has jumps


@pytest.fixture(scope="module")
def bandai_clips(tmp_path_factory) -> list[Path]:
    """Returns a few real Bandai clips read from the head of the tarball (about 1 s)."""
    if not BANDAI_TARBALL.is_file():
        pytest.skip(f"shared data not found at {BANDAI_TARBALL}")
    out = tmp_path_factory.mktemp("bandai_clips")
    paths = []
    with tarfile.open(BANDAI_TARBALL) as tf:
        for member in tf:
            if member.name.endswith(".bvh") and len(paths) < 3:
                tf.extract(member, out, filter="data")
                paths.append(out / member.name)
            if len(paths) == 3:
                break
    return paths


def test_bandai_clips(bandai_clips):
    for path in bandai_clips:
        bvh = read_bvh(path)
        assert bvh.num_joints == 22 and bvh.names[0] == "joint_Root" and bvh.names[1] == "Hips"
        assert bvh.fps == pytest.approx(30.0, rel=1e-4)
        assert all(len(c) == 6 for c in bvh.channels)  # position channels on every joint
        pos = forward_kinematics(bvh) / 100.0  # cm -> m
        lengths = bone_lengths(pos, bvh.parents)[:, 1:]  # without joint_Root -> Hips
        np.testing.assert_allclose(lengths, np.broadcast_to(lengths[0], lengths.shape), atol=1e-4)
        assert 0.35 < lengths.max() < 0.5  # shin and thigh of an adult
        assert np.all((0.6 < pos[:, 1, 1]) & (pos[:, 1, 1] < 1.2))  # Y-up, hips about 0.9 m high
