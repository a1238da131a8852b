"""MOJO's realism metrics on motions whose values can be computed by hand."""

import types

import numpy as np
import pytest

from jaxmotion.eval import realism
from jaxmotion.data.types import Skeleton

T = 8


def _frames(p):
    """(..., T, V, 3) -> (..., T, 3V)."""
    p = np.asarray(p, np.float32)
    return p.reshape(p.shape[:-2] + (-1,))


# ---------------------------------------------------------------------------------------------
# FSE


def test_impulse_has_a_flat_spectrum_and_maximal_entropy():
    x = np.zeros((T, 2), np.float32)
    x[0] = 1.0  # |FFT| = 1 at every frequency
    np.testing.assert_allclose(float(realism.spectrum_entropy(x, eps=0.0)), np.log(T), rtol=1e-6)


def test_constant_motion_has_zero_entropy_and_negative_fse():
    const = np.full((T, 3), 0.7, np.float32)  # all power at frequency 0
    assert float(realism.spectrum_entropy(const, eps=0.0)) == pytest.approx(0.0, abs=1e-6)
    gt = np.random.default_rng(0).normal(size=(T, 3)).astype(np.float32)
    assert float(realism.fse(const[None], gt)) < 0.0


@pytest.mark.slow
def test_fse_of_the_ground_truth_itself_is_zero():
    gt = np.random.default_rng(1).normal(size=(4, T, 6)).astype(np.float32)
    pred = np.repeat(gt[:, None], 5, axis=1)
    np.testing.assert_allclose(np.asarray(realism.fse(pred, gt)), 0.0, atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Body and bone deformation


HEAD = ["LFHD", "RFHD", "RBHD", "LBHD"]


def test_rigidly_moving_head_has_no_deformation():
    base = np.array([[0.1, 0.1, 1.7], [-0.1, 0.1, 1.7], [-0.1, -0.1, 1.7], [0.1, -0.1, 1.7]])
    t = np.arange(T)[:, None, None]
    c, s = np.cos(0.3 * t), np.sin(0.3 * t)
    rotated = np.stack([c[..., 0] * base[:, 0] - s[..., 0] * base[:, 1], s[..., 0] * base[:, 0] + c[..., 0] * base[:, 1],
                        np.broadcast_to(base[:, 2], (T, 4))], axis=-1) + 0.05 * t  # rotate and translate
    out = realism.body_deformation(_frames(rotated), HEAD, parts={"head": HEAD})
    assert float(out["head"]) == pytest.approx(0.0, abs=1e-3)  # mm


def test_one_marker_breathing_gives_its_distance_std_in_mm():
    # LFHD alternates between 0 and 0.2 m from the others along z: three pair distances change.
    p = np.zeros((T, 4, 3))
    p[:, 1, 0] = 1.0
    p[:, 2, 1] = 1.0
    p[:, 3, 0] = -1.0
    p[::2, 0, 2] = 0.2
    d = np.stack([np.linalg.norm(p[:, 0] - p[:, j], axis=-1) for j in (1, 2, 3)], -1)
    expected = 1000.0 * d.std(axis=0).sum()
    out = realism.body_deformation(_frames(p), HEAD, parts={"head": HEAD})
    assert float(out["head"]) == pytest.approx(expected, rel=1e-4)
    # By hand: each distance alternates between 1 and sqrt(1.04), std = half the gap.
    assert expected == pytest.approx(3 * 1000 * (np.sqrt(1.04) - 1) / 2, rel=1e-6)


BANDAI = ("Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L", "Shoulder_R",
          "UpperArm_R", "LowerArm_R", "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R",
          "LowerLeg_R", "Foot_R", "Toes_R")  # fmt: skip


def test_bone_deformation_sums_the_std_of_limb_lengths():
    rng = np.random.default_rng(0)
    p = np.repeat(rng.normal(size=(1, len(BANDAI), 3)), T, axis=0)
    assert float(realism.bone_deformation(_frames(p), BANDAI)) == pytest.approx(0.0, abs=1e-6)
    # Left forearm: the hand sits 0.3 m or 0.5 m from the elbow; std over time 0.1 m.
    i, j = BANDAI.index("LowerArm_L"), BANDAI.index("Hand_L")
    p[:, j] = p[:, i] + np.where(np.arange(T)[:, None] % 2 == 0, 0.3, 0.5) * np.array([1.0, 0.0, 0.0])
    assert float(realism.bone_deformation(_frames(p), BANDAI)) == pytest.approx(0.1, rel=1e-5)
    # Bones may be given by name, e.g. on a skeleton with other names.
    assert float(realism.bone_deformation(_frames(p), BANDAI, bones=[("LowerArm_L", "Hand_L")])) == pytest.approx(0.1, rel=1e-5)


# ---------------------------------------------------------------------------------------------
# Foot skating


HEELS = ["LHEE", "RHEE", "C7"]


def _feet(speed_mps, height, fps=30.0):
    p = np.zeros((T, 3, 3))
    p[:, :2, 0] = (np.arange(T) * speed_mps / fps)[:, None]
    p[:, :2, 2] = height
    p[:, 2, 2] = 1.5
    return _frames(p)


def test_sliding_heels_on_the_ground_skate_every_step():
    assert float(realism.foot_skating_ratio(_feet(1.0, 0.01), HEELS, fps=30.0)) == 1.0


def test_slow_or_lifted_heels_do_not_skate():
    assert float(realism.foot_skating_ratio(_feet(0.03, 0.0), HEELS, fps=30.0)) == 0.0  # 30 mm/s < 75 mm/s
    assert float(realism.foot_skating_ratio(_feet(1.0, 0.10), HEELS, fps=30.0)) == 0.0  # 10 cm above ground


def test_one_heel_planted_is_not_skating_and_ratio_counts_steps():
    p = _feet(1.0, 0.0).reshape(T, 3, 3).copy()
    p[:, 1, 0] = 0.0  # right heel planted
    assert float(realism.foot_skating_ratio(_frames(p), HEELS, fps=30.0)) == 0.0
    q = _feet(1.0, 0.0).reshape(T, 3, 3).copy()
    q[4:, :2, 0] = q[4, :2, 0]  # heels stop after frame 4: steps 1..4 of 7 skate
    assert float(realism.foot_skating_ratio(_frames(q), HEELS, fps=30.0)) == pytest.approx(4 / 7)


def test_up_axis_is_respected():
    p = _feet(1.0, 0.0).reshape(T, 3, 3).copy()
    p[:, :2, 1] = 0.5
    p = p[..., [0, 2, 1]]  # y up; z is now 0.5 m
    assert float(realism.foot_skating_ratio(_frames(p), HEELS, fps=30.0, up_axis=1)) == 1.0
    assert float(realism.foot_skating_ratio(_frames(p), HEELS, fps=30.0, up_axis=2)) == 0.0


# ---------------------------------------------------------------------------------------------
# Errors and the evaluation hook


def test_missing_names_are_listed():
    with pytest.raises(ValueError, match=r"lacks \['RBHD', 'LBHD'\]"):
        realism.body_deformation(np.zeros((T, 6)), ["LFHD", "RFHD"], parts={"head": HEAD})
    with pytest.raises(ValueError, match="LHEE"):
        realism.foot_skating_ratio(np.zeros((T, 3)), ["C7"], fps=30.0)
    with pytest.raises(ValueError, match=r"bandai naming lacks \[.*Hand_L"):
        realism.bone_deformation(np.zeros((T, 3)), ["UpperArm_L"])
    with pytest.raises(ValueError, match="D = 5"):
        realism.bone_deformation(np.zeros((T, 5)), BANDAI)


@pytest.mark.slow
def test_window_realism_reports_what_the_dataset_supports():
    rng = np.random.default_rng(0)
    names = ("Hips",) + BANDAI
    ds = types.SimpleNamespace(skeleton=Skeleton(names, tuple([-1] + [0] * len(BANDAI))), info={}, fps=30.0)
    gt = rng.normal(size=(2, T, 3 * len(BANDAI))).astype(np.float32)
    out = realism.window_realism(np.repeat(gt[:, None], 3, axis=1), gt, ds)
    assert set(out) == {"FSE", "BDF"} and out["FSE"].shape == (2,)
    np.testing.assert_allclose(out["FSE"], 0.0, atol=1e-5)
    markers = HEAD + ["LHEE", "RHEE"]
    ds = types.SimpleNamespace(skeleton=None, info={"point_names": markers, "frames": "global", "up_axis": 2}, fps=30.0)
    gt = rng.normal(size=(2, T, 3 * len(markers))).astype(np.float32)
    out = realism.window_realism(gt[:, None], gt, ds)
    assert set(out) == {"FSE", "deform_head", "foot_skating"}
