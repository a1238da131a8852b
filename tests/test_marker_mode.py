"""Marker datasets through the pipeline: canonical windows (protocol §5 (docs/pages/protocol.md#marker-canonicalisation)), marker bone deformation,
and MOJO with recursive projection as an evaluation sampler, on fabricated motion of the built-in body."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion import experiment
from jaxmotion.eval import realism
from jaxmotion.body.markersets import LIMB_MARKER_PAIRS
from jaxmotion.body.skeleton import toy_skeleton
from jaxmotion.data.markers import canonical_frames, canonicalise, marker_skeleton
from jaxmotion.data.types import MotionDataset, Sequence
from jaxmotion.data.windows import TrainSampler, canonicalise_windows

BODY = toy_skeleton("bandai")
T_HIS, T_PRED = 4, 5


def motion(seed: int, n: int, yaw: float = 0.0, shift=(0.0, 0.0, 0.0)):
    """Returns `(markers (n, M, 3), joints (n, J, 3))` of smooth random motion (Y up), turned and moved."""
    rng = np.random.default_rng(seed)
    p = BODY.zero_params()
    pose = np.cumsum(0.05 * rng.standard_normal((n, p.pose.shape[0])), axis=0)
    walk = np.cumsum(0.02 * rng.standard_normal((n, 3)), axis=0) * np.array([1.0, 0.0, 1.0])
    rep = lambda a: jnp.broadcast_to(a, (n,) + a.shape)  # noqa: E731
    params = p._replace(
        transl=rep(p.transl) + jnp.asarray(walk, jnp.float32), orient=rep(p.orient), shape=rep(p.shape),
        pose=jnp.asarray(pose, jnp.float32), hand=rep(p.hand),
    )  # fmt: skip
    mk, jt = np.asarray(jax.vmap(BODY.markers)(params)), np.asarray(jax.vmap(BODY.joints)(params))
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return mk @ rot.T + np.asarray(shift), jt @ rot.T + np.asarray(shift)


def seq(seed: int, n: int, **kw) -> Sequence:
    mk, jt = motion(seed, n, **kw)
    return Sequence(mk.astype(np.float32), 30.0, "s", "a", name=f"s{seed}", canon=canonical_frames(jt, BODY.names))


def dataset(train, test) -> MotionDataset:
    return MotionDataset(
        "toy_markers", marker_skeleton(BODY.marker_names), 30.0, T_HIS, T_PRED, 0.5, train, test,
        info={"frames": "global", "up_axis": 2, "ground": "future_heel_min", "point_names": BODY.marker_names, "body": BODY},
    )  # fmt: skip


@pytest.mark.slow
def test_canonical_windows_do_not_depend_on_where_and_which_way_the_motion_happens():
    a = dataset([seq(0, 30)], [seq(0, 30)])
    b = dataset([seq(0, 30, yaw=2.1, shift=(3.0, 0.0, -1.0))], [seq(0, 30, yaw=-0.7, shift=(-5.0, 0.0, 2.0))])
    pa, pb = experiment.prepare(a), experiment.prepare(b)
    assert pa.windows.shape == (len(range(0, 30 - T_HIS - T_PRED, T_HIS)), T_HIS + T_PRED, 3 * BODY.num_markers)
    np.testing.assert_allclose(pa.windows, pb.windows, atol=2e-5)
    wa = pa.sampler.sample(np.random.default_rng(3), 8)
    wb = pb.sampler.sample(np.random.default_rng(3), 8)
    np.testing.assert_allclose(wa, wb, atol=2e-5)
    # Canonical frame (protocol §5 (docs/pages/protocol.md#marker-canonicalisation)): origin at the first frame's root, Z up, left hip -> right hip along +X.
    mk, jt = motion(1, 12, yaw=0.4)
    x = canonicalise(mk, jt, BODY.names).reshape(12, -1)
    np.testing.assert_allclose(canonicalise_windows(mk.reshape(1, 12, -1), canonical_frames(jt, BODY.names)[:1])[0], x, atol=1e-5)
    j0 = canonicalise(jt, jt, BODY.names)[0]
    np.testing.assert_allclose(j0[0], 0.0, atol=1e-6)
    hips = j0[BODY.names.index("RightUpLeg")] - j0[BODY.names.index("LeftUpLeg")]
    assert hips[0] > 0.1 and abs(hips[1]) < 1e-6
    assert np.all(canonicalise(mk, jt, BODY.names)[..., 2].max(-1) > 0.3)  # the head is above the root: Z up


@pytest.mark.slow
def test_missing_canonical_frames_are_named():
    s = seq(0, 20)
    bad = dataset([dataclasses.replace(s, canon=None)], [s])
    with pytest.raises(ValueError, match="canon"):
        experiment.prepare(bad)
    with pytest.raises(ValueError, match="canonical-frame"):
        TrainSampler([np.zeros((20, 3))], 9, canon=[])


@pytest.mark.slow
def test_marker_bone_deformation_is_zero_for_a_valid_body_and_the_override_makes_it_so():
    mk, _ = motion(2, 40)
    frames = jnp.asarray(mk.reshape(1, 40, -1))
    bdf = realism.bone_deformation(frames, BODY.marker_names)
    assert realism.find_limb_bones(BODY.marker_names) == LIMB_MARKER_PAIRS
    assert float(bdf[0]) < 1e-5
    # With the generic cmu41 attachments the elbow/wrist/knee/ankle markers ride the next bone.
    generic = toy_skeleton("cmu41")
    p = jax.tree.map(lambda a: jnp.broadcast_to(a, (40,) + a.shape), generic.zero_params())
    p = p._replace(pose=jnp.asarray(np.cumsum(0.05 * np.random.default_rng(2).standard_normal((40, p.pose.shape[1])), 0), jnp.float32))
    mk2 = jax.vmap(generic.markers)(p).reshape(1, 40, -1)
    assert float(realism.bone_deformation(mk2, generic.marker_names)[0]) > 1e-3
    # Stretching one forearm shows up.
    i = BODY.marker_names.index("LWRA")
    stretched = mk.copy()
    stretched[::2, i] += np.array([0.0, -0.05, 0.0])
    assert float(realism.bone_deformation(jnp.asarray(stretched.reshape(1, 40, -1)), BODY.marker_names)[0]) > 0.01


@pytest.mark.slow
def test_mojo_with_recursive_projection_keeps_bones_rigid_and_matches_mojo_latents():
    from jaxmotion.config import Config
    from jaxmotion.models.mojo import MojoConfig
    from jaxmotion.train.runner import init_state

    ds = dataset([seq(i, 40) for i in range(3)], [seq(9, 40)])
    prep = experiment.prepare(ds)
    m = MojoConfig(nz=4, nh_rnn=8, nh_mlp=(8,), q_nh_rnn=8, q_nh_mlp=(8,), baselines=("mojo_proj",), proj_max_steps=5)
    cfg = Config(method="mojo", method_config=m, eval_k=(3,), action_metrics=False)
    params = {}
    for stage in experiment.get_method("mojo").stages(cfg, prep):
        params[stage.name] = init_state(stage, params).params
    assert sorted(params) == ["cvae", "q_k3"]
    preds = experiment.predictors(cfg, ds, params, 3)
    x = jnp.asarray(prep.x[:2])
    key = jax.random.key(0)
    raw, proj = preds["mojo"](x, key), preds["mojo_proj"](x, key)
    assert raw.shape == proj.shape == (2, 3, T_PRED, 3 * BODY.num_markers)
    assert np.all(np.isfinite(np.asarray(proj)))
    names = BODY.marker_names
    assert float(realism.bone_deformation(raw, names).mean()) > 1e-3  # an untrained decoder deforms bodies
    assert float(realism.bone_deformation(proj, names).max()) < 1e-4  # projected frames are the body's markers
    # Projection moves the frames onto a body near the decoder's output; it does not replace them.
    assert float(jnp.abs(proj - raw).mean()) > 0.0
    # The realism hook evaluates every metric on marker data, foot skating included.
    r = realism.window_realism(np.asarray(proj), prep.y[:2], ds)
    assert {"FSE", "BDF", "deform_head", "deform_upper_torso", "deform_lower_torso", "foot_skating"} <= set(r)


@pytest.mark.slow
def test_projection_sampler_needs_a_body():
    from jaxmotion.config import Config
    from jaxmotion.models.mojo import MojoConfig

    ds = dataset([seq(0, 30)], [seq(1, 30)])
    ds.info.pop("body")
    m = MojoConfig(nz=4, nh_rnn=8, nh_mlp=(8,), q_nh_rnn=8, q_nh_mlp=(8,), baselines=("mojo_proj",))
    cfg = Config(method="mojo", method_config=m, eval_k=(3,), action_metrics=False)
    with pytest.raises(ValueError, match="body model"):
        experiment.predictors(cfg, ds, {"cvae": None, "q_k3": None}, 3)
    with pytest.raises(ValueError, match="proj_max_steps"):
        MojoConfig(proj_max_steps=0)
