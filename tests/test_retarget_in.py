"""A body of other proportions and facing than the training data's: retargeted onto the model, futures back on its bones."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.body.bones import bone_lengths, bone_vectors, motion_transfer, with_bone_lengths
from jaxmotion.data.synthetic import make_synthetic
from jaxmotion.eval.metrics import first_frame_error
from jaxmotion.tools.predictor import retargeted
from jaxmotion.train.manifest import facing, facing_angle, hip_pair

# Root, spine, head; left hip, knee; right hip, knee; a left clavicle of zero length, its arm.
NAMES = ("Hips", "Spine", "Head", "UpperLeg_L", "LowerLeg_L", "UpperLeg_R", "LowerLeg_R", "Shoulder_L", "UpperArm_L")
PARENTS = (-1, 0, 1, 0, 3, 0, 5, 1, 7)


def _frames(rng, n=(4, 15), zero_clavicle=False):
    """Returns random root-relative frames (..., D) of the skeleton above, bones 0.1-0.5 m."""
    dirs = rng.normal(size=n + (len(PARENTS) - 1, 3))
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    lengths = rng.uniform(0.1, 0.5, len(PARENTS) - 1)
    if zero_clavicle:
        lengths[NAMES.index("Shoulder_L") - 1] = 0.0
    joints = []
    for j, p in enumerate(PARENTS[1:], start=1):
        base = joints[p - 1] if p > 0 else 0.0
        joints.append(base + lengths[j - 1] * dirs[..., j - 1, :])
    return np.stack(joints, axis=-2).reshape(n + (-1,)).astype(np.float32), lengths


def _turn(frames, degrees):  # about y, as `manifest.facing_angle` measures it (from z towards x)
    a = np.radians(degrees)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], np.float32)
    j = frames.reshape(frames.shape[:-1] + (-1, 3))
    return (j @ rot.T).reshape(frames.shape)


def test_with_bone_lengths_keeps_directions_and_takes_the_lengths():
    x, _ = _frames(np.random.default_rng(0))
    want = np.linspace(0.2, 0.6, len(PARENTS) - 1).astype(np.float32)
    got = with_bone_lengths(x, want, PARENTS)
    np.testing.assert_allclose(bone_lengths(got, PARENTS), np.broadcast_to(want, got.shape[:-1] + want.shape), rtol=1e-5)
    u = lambda f: np.asarray(bone_vectors(f, PARENTS)) / np.asarray(bone_lengths(f, PARENTS))[..., None]  # noqa: E731
    np.testing.assert_allclose(u(got), u(x), atol=1e-5)
    # MotionMap's motion transfer is the same operation with the target's lengths.
    np.testing.assert_allclose(motion_transfer(jnp.asarray(x), got[:1, :1], PARENTS), got, atol=1e-6)


def test_a_zero_length_bone_borrows_its_childs_direction():
    x, _ = _frames(np.random.default_rng(1), zero_clavicle=True)
    ones = np.ones(len(PARENTS) - 1, np.float32)
    kept = with_bone_lengths(x, ones, PARENTS)
    borrowed = with_bone_lengths(x, ones, PARENTS, borrow_direction=True)
    c, a = NAMES.index("Shoulder_L") - 1, NAMES.index("UpperArm_L") - 1
    assert float(jnp.abs(bone_lengths(kept, PARENTS)[..., c]).max()) == 0.0  # no direction: stays at the parent
    bones = np.asarray(bone_vectors(borrowed, PARENTS))
    np.testing.assert_allclose(bones[..., c, :], bones[..., a, :], atol=1e-5)  # the clavicle points along its arm
    np.testing.assert_allclose(np.linalg.norm(bones, axis=-1), np.ones(bones.shape[:-1]), rtol=1e-5)


def test_first_frame_error_is_the_best_futures_first_frame_distance():
    gt = np.zeros((2, 5, 6), np.float32)
    pred = np.zeros((2, 3, 5, 6), np.float32)
    pred[0, :, 0, 0] = [0.3, 0.1, 0.2]  # window 0: its best first frame is 0.1 away
    pred[1, :, 0, 1] = [0.5, 0.4, 0.6]
    pred[1, 1, 1:] = 9.0  # later frames do not count
    np.testing.assert_allclose(first_frame_error(pred, gt), [0.1, 0.4], rtol=1e-6)


def _model_fn(x, key):
    """A stand-in model that is neither rotation- nor scale-equivariant: it pushes the last pose along +x, growing."""
    del key
    last = x[:, None, -1:, :]  # (b, 1, 1, D)
    steps = jnp.arange(1, 4, dtype=x.dtype)[None, None, :, None]
    push = jnp.tile(jnp.array([0.05, 0.0, 0.0], x.dtype), x.shape[-1] // 3)
    return last + steps * push + 0.01 * steps * last  # (b, 1, 3, D)


MODEL_LENGTHS = np.linspace(0.15, 0.45, len(PARENTS) - 1).astype(np.float32)
MODEL_FACING = (-95.0, NAMES.index("UpperLeg_L"), NAMES.index("UpperLeg_R"), 1)


def test_retargeted_model_sees_its_own_skeleton_and_facing_whatever_the_input():
    """Turning or resizing the input turns or resizes the futures alike: the model saw the same window each time."""
    x, _ = _frames(np.random.default_rng(2))
    fn = retargeted(_model_fn, MODEL_LENGTHS, PARENTS, MODEL_FACING)
    key = jax.random.key(0)
    base = np.asarray(fn(x, key))
    np.testing.assert_allclose(np.asarray(fn(_turn(x, 70.0), key)), _turn(base, 70.0), atol=2e-5)
    bigger = np.asarray(fn(1.3 * x, key))
    np.testing.assert_allclose(bigger, 1.3 * base, atol=2e-5)
    # The futures are on the bones of each window's last observed frame.
    own = np.asarray(bone_lengths(x[:, -1], PARENTS))[:, None, None]
    np.testing.assert_allclose(bone_lengths(base, PARENTS), np.broadcast_to(own, base.shape[:-1] + own.shape[-1:]), rtol=1e-4)
    # Without retargeting the same stand-in answers differently to a turned input.
    assert np.abs(np.asarray(_model_fn(_turn(x, 70.0), key)) - _turn(np.asarray(_model_fn(x, key)), 70.0)).max() > 0.01


def test_retargeted_standing_still_stays_still():
    x, _ = _frames(np.random.default_rng(3))
    still = lambda x, key: jnp.repeat(x[:, None, -1:], 4, axis=2)  # noqa: E731  (zero-velocity, K = 1)
    out = np.asarray(retargeted(still, MODEL_LENGTHS, PARENTS, MODEL_FACING)(x, jax.random.key(0)))
    np.testing.assert_allclose(out, np.repeat(x[:, None, -1:], 4, axis=2), atol=2e-5)


def test_facing_is_the_training_datas_most_common_hip_direction():
    ds = make_synthetic(0, train_sequences=2, train_segments=2, test_sequences=1, test_segments=2)
    hips = hip_pair(ds.skeleton.names, ds.skeleton.parents)
    assert facing(ds) is None  # no up axis recorded: no facing to turn to
    ds = dataclasses.replace(ds, info={**ds.info, "up_axis": 1})
    turned = [dataclasses.replace(s, positions=_turn(s.positions.reshape(len(s.positions), -1), 40.0).reshape(s.positions.shape))
              for s in ds.train]
    assert abs(facing(dataclasses.replace(ds, train=turned))["degrees"] - facing(ds)["degrees"] - 40) <= 10
    f = facing(ds)
    angles = np.concatenate([facing_angle(s.positions, hips, ds.info["up_axis"]) for s in ds.train])
    assert f["left"] == ds.skeleton.names[hips[0]] and f["right"] == ds.skeleton.names[hips[1]]
    assert ds.skeleton.names[hips[0]] == "LHip" and np.mean(np.abs((angles - f["degrees"] + 180) % 360 - 180) <= 10) > 0.2


def test_inertialized_futures_continue_the_observed_velocity_then_become_the_models():
    from jaxmotion.tools.predictor import inertialized

    rng = np.random.default_rng(4)
    x = rng.normal(size=(2, 15, 6)).astype(np.float32)
    f = rng.normal(size=(2, 3, 20, 6)).astype(np.float32)
    out = np.asarray(inertialized(jnp.asarray(f), jnp.asarray(x), 8))
    np.testing.assert_allclose(out[:, :, 0], np.broadcast_to((2 * x[:, -1] - x[:, -2])[:, None], (2, 3, 6)), atol=1e-5)
    np.testing.assert_array_equal(out[:, :, 8:], f[:, :, 8:])  # from the blend's end on: the model's own futures
    # In between, each future moves by its first frame's shift, scaled by a weight that falls from 1 to 0.
    shift = out - f
    w = shift[:, :, :8, 0] / shift[:, :, :1, 0]
    np.testing.assert_allclose(shift[:, :, :8], w[..., None] * shift[:, :, :1], atol=1e-5)
    np.testing.assert_allclose(w, np.broadcast_to(w[0, 0], w.shape), atol=1e-5)
    assert w[0, 0, 0] == 1 and np.all(np.diff(w[0, 0]) < 0) and w[0, 0, -1] > 0
    np.testing.assert_array_equal(np.asarray(inertialized(jnp.asarray(f), jnp.asarray(x), 0)), f)
