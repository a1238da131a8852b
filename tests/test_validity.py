"""Validity metrics for any method's predictions (angle-limit violations, pose-prior NLL) and GSPS's single-future skip."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxmotion.eval import validity
from jaxmotion.data.synthetic import SKELETON, make_synthetic
from jaxmotion.data.windows import sequence_frames
from jaxmotion.models import gsps
from jaxmotion.eval import evaluate_windows

NAMES, PARENTS = tuple(SKELETON.names), tuple(SKELETON.parents)
ELBOW = gsps.ANGLE_NAMES.index("ForeArm2ArmPlane_l")


def _pose(left_elbow_deg: float, right_elbow_deg: float = 60.0) -> np.ndarray:
    """Returns one standing frame vector (root dropped) of the synthetic skeleton, built by hand.

    Axes (right-handed): x to the body's right, y forward, z up. The forearms swing in the sagittal
    plane: 0 deg hangs straight down, positive bends the elbow forward (flexion), negative backwards.
    """
    j = {
        "Hips": (0, 0, 0), "RHip": (0.1, 0, 0), "RKnee": (0.1, 0.03, -0.45), "RFoot": (0.1, 0, -0.9),
        "LHip": (-0.1, 0, 0), "LKnee": (-0.1, 0.03, -0.45), "LFoot": (-0.1, 0, -0.9), "Spine": (0, 0, 0.25),
        "Thorax": (0, 0, 0.5), "Neck": (0, 0, 0.6), "Head": (0, 0.02, 0.72), "LShoulder": (-0.18, 0, 0.5),
        "LElbow": (-0.18, 0, 0.22), "RShoulder": (0.18, 0, 0.5), "RElbow": (0.18, 0, 0.22),
    }
    for side, deg in (("L", left_elbow_deg), ("R", right_elbow_deg)):
        a = np.deg2rad(deg)
        j[f"{side}Wrist"] = tuple(np.asarray(j[f"{side}Elbow"]) + 0.25 * np.array([0.0, np.sin(a), -np.cos(a)]))
    return np.asarray([j[n] for n in NAMES[1:]], np.float32).reshape(-1)


def _prior(n_layers: int):
    prior = gsps.PosePrior(dim=48, n_layers=n_layers)
    return prior, jax.jit(prior.init)(jax.random.key(0), jnp.zeros((1, 48)))  # jitted: the eager scans compile slower


def _hand_made_validity() -> validity.PoseValidity:
    """Bounds measured on hand-made poses whose elbows flex forward 20-130 deg (nothing else moves)."""
    flex = np.linspace(20, 130, 45)
    train = np.stack([_pose(a, b) for a in flex for b in flex[::4]])
    bounds = gsps.measure_angle_bounds(train, gsps.angle_roles(NAMES, PARENTS), 0.1, margin=0.05)
    prior, params = _prior(n_layers=1)  # untrained: only the angles are under test
    return validity.PoseValidity(NAMES, PARENTS, bounds, prior, params)


def test_pose_inside_the_bounds_has_no_violation_and_a_backward_elbow_has_one():
    v = _hand_made_validity()
    inside = np.stack([_pose(a, b) for a, b in ((35, 50), (75, 100), (120, 30))])  # 3 frames inside the range
    backward = np.stack([_pose(-40)] * 3)  # the left elbow bent backwards 40 deg in every frame
    half = np.stack([_pose(-40), _pose(80), _pose(-25), _pose(60)])  # 2 of 4 frames backwards
    pred = np.zeros((2, 2, 4, 48), np.float32)
    pred[0, 0, :3], pred[0, 0, 3] = inside, inside[0]
    pred[0, 1] = pred[0, 0][::-1]
    pred[1, 0, :3], pred[1, 0, 3] = backward, backward[0]
    pred[1, 1] = half
    out = validity.window_validity(v, pred)
    np.testing.assert_allclose(out["angle_violation"], [0.0, (1.0 + 0.5) / 2])
    # The backward elbow leaves exactly one bound: the forearm against the arm plane, on the left.
    viol = gsps.angle_violations(gsps.angle_cosines(jnp.asarray(backward[:1]), gsps.angle_roles(NAMES, PARENTS)), jnp.asarray(v.bounds))
    assert np.flatnonzero(np.asarray(viol[0]) > 0).tolist() == [ELBOW]
    # The hand-made limbs keep their lengths, so the bone deformation is 0 up to rounding.
    assert float(np.max(out["BDF"])) < 1e-6
    with pytest.raises((TypeError, ValueError)):  # jaxtyping (under the test hook) or the shape check
        validity.window_validity(v, pred[0])


def test_prior_nll_is_finite_matches_the_flow_and_is_lower_for_training_poses_than_for_noise():
    ds = make_synthetic(0, train_sequences=2, train_segments=4, test_sequences=1, test_segments=2)
    train = np.concatenate(sequence_frames(ds.train))
    prior, params = _prior(n_layers=2)  # one PReLU: the log-determinant then depends on the pose
    tx = optax.adam(1e-2)
    opt = tx.init(params)

    @jax.jit
    def step(params, opt, frames):
        g = jax.grad(lambda p: gsps.prior_loss(prior, p, frames, parents=PARENTS)[0])(params)
        up, opt = tx.update(g, opt, params)
        return optax.apply_updates(params, up), opt

    rng = np.random.default_rng(0)
    for _ in range(60):
        params, opt = step(params, opt, jnp.asarray(train[rng.integers(0, len(train), 256)]))
    v = validity.PoseValidity(NAMES, PARENTS, np.tile([[-1.0, 1.0]], (len(gsps.ANGLE_NAMES), 1)).astype(np.float32), prior, params)
    real = train[rng.integers(0, len(train), (4, 3, 10))]  # (n, K, t, D) training poses
    noise = rng.normal(0, 0.3, real.shape).astype(np.float32)
    s_real, s_noise = validity.sample_validity(v, real), validity.sample_validity(v, noise)
    assert all(bool(np.all(np.isfinite(a))) for a in (*s_real.values(), *s_noise.values()))
    # prior_nll is -log p of the flow per frame (log-determinant included), averaged over the frames.
    ref = np.asarray(gsps.prior_nll(prior, params, jnp.asarray(real), PARENTS)).mean(-1)
    np.testing.assert_allclose(s_real["prior_nll"], ref, rtol=1e-4, atol=1e-3)
    assert float(jnp.max(s_real["prior_nll"])) + 20.0 < float(jnp.min(s_noise["prior_nll"]))
    assert float(jnp.max(s_real["prior_nll_z"])) < float(jnp.min(s_noise["prior_nll_z"]))
    assert np.all(np.asarray(s_noise["angle_violation"]) == 0.0)  # open bounds never apply


def test_check_skeleton_names_the_mismatch():
    v = validity.PoseValidity(NAMES, PARENTS, np.zeros((len(gsps.ANGLE_NAMES), 2), np.float32), None, None)
    validity.check_skeleton(v, NAMES, PARENTS, "run")
    with pytest.raises(ValueError, match="not the GSPS run's"):
        validity.check_skeleton(v, NAMES[:-1], PARENTS[:-1], "run")


def test_gsps_single_future_skip_is_the_protocol_on_windows_with_a_neighbour():
    from jaxmotion import experiment
    from jaxmotion.eval import metrics
    from jaxmotion.methods import get_method

    ds = make_synthetic(0, train_sequences=1, train_segments=3, test_sequences=2, test_segments=3)
    prep = experiment.prepare(ds)
    sets = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold)
    alone = np.asarray(sets.mask).sum(1) == 1
    assert alone.any() and not alone.all()  # the test below needs both kinds of window
    from jaxmotion.config import Config
    from jaxmotion.eval import loop, protocol

    kept = loop.select_windows(prep, protocol.multi_future_windows(prep.x[:, -1], ds.mm_threshold))
    np.testing.assert_array_equal(kept.keep, prep.keep[~alone])
    np.testing.assert_array_equal(kept.windows, prep.windows[~alone])
    # The release's loop: every metric of the windows with a neighbour, averaged over those windows.
    pred = np.asarray(jax.random.normal(jax.random.key(0), (len(prep.windows), 3) + prep.y.shape[1:]), np.float32) * 0.1
    pred += prep.y[:, None]
    per = metrics.window_metrics(pred, prep.y, prep.y, sets.idx, sets.mask)
    got = evaluate_windows(pred[~alone], kept.y, kept.x[:, -1], thr=ds.mm_threshold)
    for k in ("APD", "ADE", "FDE", "MMADE", "MMFDE"):
        np.testing.assert_allclose(got[k], per[k][~alone].mean(), rtol=1e-5)
    train_ref = dataclasses.replace(get_method("gsps"), reference_futures="train")
    cfg = experiment.resolve(Config(method="gsps", mm_deviation="gsps", action_metrics=False))
    with pytest.raises(ValueError, match="test-window reference futures"):
        loop.evaluators(cfg, train_ref, prep, {})
