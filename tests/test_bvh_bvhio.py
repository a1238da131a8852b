"""BVH files jaxmotion writes (`formats.bvh_write`) as bvhio reads them (a maintained BVH library, `pip install bvhio`).

Same hierarchy (names, parents, offsets), channels, frame count and frame time; the root's position
channels as bvhio's keyframe positions, every joint's rotation channels as bvhio's keyframe
rotations, and bvhio's world positions (its own forward kinematics) as `formats.bvh.forward_kinematics`.
Skipped when bvhio is not installed.
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxmotion.formats.bvh import Bvh, euler_matrices, forward_kinematics
from jaxmotion.formats.bvh_write import write_bvh

bvhio = pytest.importorskip("bvhio", reason="bvhio not installed (pip install bvhio): no reference BVH reader")
glm = pytest.importorskip("glm")

ROT = ("Zrotation", "Xrotation", "Yrotation")


def skeleton(frames: int, seed: int = 0) -> Bvh:
    """Returns a 6-joint, two-branch skeleton in mixed rotation orders with random motion (a joint with position channels too)."""
    rng = np.random.default_rng(seed)
    names = ("Hips", "Spine", "Head", "LeftLeg", "LeftFoot", "RightLeg")
    parents = (-1, 0, 1, 0, 3, 0)
    offsets = np.array([[0, 90, 0], [0, 10, 2], [0, 25, 0], [9, -4, 0], [0, -40, 3], [-9, -4, 0]], float)
    channels = (
        ("Xposition", "Yposition", "Zposition") + ROT, ("Xrotation", "Yrotation", "Zrotation"),
        ("Yrotation", "Zrotation", "Xrotation"), ROT, ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
        ("Xrotation", "Zrotation", "Yrotation"),
    )  # fmt: skip
    motion = []
    for j, ch in enumerate(channels):
        for c in ch:
            if c.endswith("position"):
                base = offsets[j]["XYZ".index(c[0])]
                motion.append(base + np.cumsum(rng.normal(0, 0.5, frames)))
            else:
                motion.append(rng.uniform(-80, 80, frames))
    return Bvh(names, parents, offsets, channels, np.stack(motion, 1), 1 / 30)


def quat_matrix(q) -> np.ndarray:
    return np.array(glm.mat3_cast(q).to_list()).T  # glm is column-major


def test_bvhio_reads_what_jaxmotion_writes(tmp_path):
    bvh = skeleton(12)
    path = write_bvh(tmp_path / "mixed.bvh", bvh)
    c = bvhio.readAsBvh(str(path))
    layout = c.Root.layout()
    joints = [j for j, _, _ in layout]
    assert tuple(j.Name for j in joints) == bvh.names
    index = {j.Name: i for i, j in enumerate(joints)}
    parents = [-1] * len(joints)
    for j in joints:
        for ch in j.Children:
            parents[index[ch.Name]] = index[j.Name]
    assert tuple(parents) == bvh.parents
    np.testing.assert_allclose([list(j.Offset) for j in joints], bvh.offsets, atol=1e-5)
    assert tuple(tuple(j.Channels) for j in joints) == bvh.channels
    assert c.FrameCount == bvh.num_frames and abs(c.FrameTime - bvh.frame_time) < 1e-6
    start = np.cumsum([0] + [len(ch) for ch in bvh.channels])
    for j, joint in enumerate(joints):
        ch = bvh.channels[j]
        vals = bvh.motion[:, start[j] : start[j + 1]]
        assert len(joint.Keyframes) == bvh.num_frames
        rot = [i for i, n in enumerate(ch) if n.endswith("rotation")]
        want = euler_matrices(vals[:, rot], "".join(ch[i][0] for i in rot))  # (F, 3, 3)
        got = np.stack([quat_matrix(k.Rotation) for k in joint.Keyframes])
        np.testing.assert_allclose(got, want, atol=1e-5)
        pos = [i for i, n in enumerate(ch) if n.endswith("position")]
        if pos:
            np.testing.assert_allclose([list(k.Position) for k in joint.Keyframes], vals[:, pos], atol=1e-4)
    # bvhio's own forward kinematics: world positions of every joint at every frame.
    root = bvhio.readAsHierarchy(str(path))
    by_name = {j.Name: j for j, _, _ in root.layout()}
    fk = forward_kinematics(bvh)  # (F, J, 3)
    for f in range(bvh.num_frames):
        root.loadPose(f)
        got = np.array([list(by_name[n].PositionWorld) for n in bvh.names])
        np.testing.assert_allclose(got, fk[f], atol=1e-3)  # file units (cm): printed to 1e-6, float32 in glm
