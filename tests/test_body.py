"""Body models: rotations, skeleton forward kinematics against the BVH reader, marker attachment, SMPL-X."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.body import rotation as rot
from jaxmotion.body.markersets import MARKER_SETS
from jaxmotion.body.skeleton import attach_markers, params_from_bvh, skeleton_body_from_bvh, toy_skeleton
from jaxmotion.body.smplx import NUM_JOINTS, load_smplx

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
CMU_01_01 = SHARED_DATA / "cmu-bvh" / "01_01.bvh"

# SMPL-X's kinematic tree (smplx.SMPLX parents): pelvis, 21 body joints, jaw, eyes, 2 x 15 hand joints.
SMPLX_PARENTS = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15,
    20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,
    21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53,
)  # fmt: skip


def random_rotations(key, n):
    return rot.axis_angle_to_matrix(jax.random.normal(key, (n, 3)))


def test_rot6d_roundtrip_and_orthonormal():
    r = random_rotations(jax.random.key(0), 16)
    np.testing.assert_allclose(rot.rot6d_to_matrix(rot.matrix_to_rot6d(r)), r, atol=1e-5)
    # Any 6-D vector maps to a proper rotation.
    m = rot.rot6d_to_matrix(jax.random.normal(jax.random.key(1), (16, 6)))
    np.testing.assert_allclose(m @ jnp.swapaxes(m, -1, -2), jnp.broadcast_to(jnp.eye(3), m.shape), atol=1e-5)
    np.testing.assert_allclose(jnp.linalg.det(m), 1.0, atol=1e-5)
    np.testing.assert_allclose(rot.rot6d_to_matrix(jnp.asarray(rot.IDENTITY_6D)), jnp.eye(3), atol=1e-7)


@pytest.mark.slow
def test_axis_angle_is_the_matrix_exponential_with_finite_gradient_at_zero():
    v = 0.7 * jax.random.normal(jax.random.key(2), (8, 3))
    expm = jax.vmap(jax.scipy.linalg.expm)(rot.skew(v))
    np.testing.assert_allclose(rot.axis_angle_to_matrix(v), expm, atol=1e-5)
    np.testing.assert_allclose(rot.axis_angle_to_matrix(rot.matrix_to_axis_angle(expm)), expm, atol=1e-5)
    g = jax.jacfwd(rot.axis_angle_to_matrix)(jnp.zeros(3))
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g[..., 0], rot.skew(jnp.array([1.0, 0.0, 0.0])), atol=1e-6)


def test_kabsch_recovers_a_rigid_motion_with_weights():
    src = jax.random.normal(jax.random.key(3), (10, 3))
    r = random_rotations(jax.random.key(4), 1)[0]
    t = jnp.array([0.3, -1.0, 2.0])
    dst = src @ r.T + t
    w = jnp.ones(10).at[3].set(0.0)
    dst = dst.at[3].set(100.0)  # a zero-weight outlier is ignored
    r2, t2 = rot.kabsch(src, dst, w)
    np.testing.assert_allclose(r2, r, atol=1e-4)
    np.testing.assert_allclose(t2, t, atol=1e-4)


def test_marker_sets_have_the_published_sizes_and_unique_names():
    for name, n in (("cmu41", 41), ("vicon53", 53), ("ssm2_67", 67)):
        assert len(MARKER_SETS[name]) == n == len(set(MARKER_SETS[name]))


def test_toy_skeleton_markers_sit_where_the_specs_say():
    body = toy_skeleton("ssm2_67")
    p = body.zero_params()
    joints, markers = np.asarray(body.joints(p)), np.asarray(body.markers(p))
    assert len(body.names) == len(joints) > 0 and len(body.marker_names) == len(markers) > 0
    j = dict(zip(body.names, joints))
    m = dict(zip(body.marker_names, markers))
    # Y up, facing +Z, left = +X: ARIEL 19 cm above the head joint, LKNE 5 cm lateral of the knee.
    np.testing.assert_allclose(m["ARIEL"], j["Head"] + [0, 0.19, 0], atol=1e-6)
    np.testing.assert_allclose(m["LKNE"], j["LeftLeg"] + [0.05, 0, 0], atol=1e-6)
    np.testing.assert_allclose(m["RKNE"], j["RightLeg"] + [-0.05, 0, 0], atol=1e-6)
    np.testing.assert_allclose(m["LTOE"], j["LeftToeBase"] + [0, -0.02, 0.05], atol=1e-6)


def test_markers_move_rigidly_with_their_bone():
    body = toy_skeleton()
    p = body.zero_params()
    knee = body.names.index("LeftLeg")
    pose = p.pose.at[3 * (knee - 1)].set(1.2)  # bend the left knee only
    q = p._replace(pose=pose)
    names = body.marker_names
    m0, m1 = np.asarray(body.markers(p)), np.asarray(body.markers(q))
    assert len(names) == len(m0) == len(m1) > 0
    moved = {n for n, a, b in zip(names, m0, m1) if np.linalg.norm(a - b) > 1e-6}
    assert moved == {"LSHN", "LANK", "LHEE", "LTOE", "LMT5", "LKNE"} - {"LKNE"}
    # Distances between markers of the shin stay the same (rigid attachment).
    i, k = names.index("LSHN"), names.index("LHEE")
    assert abs(np.linalg.norm(m0[i] - m0[k]) - np.linalg.norm(m1[i] - m1[k])) < 1e-5


def test_bone_length_shape_scales_bones():
    body = toy_skeleton()
    p = body.zero_params()
    shin = body.names.index("LeftFoot")
    q = p._replace(shape=p.shape.at[shin - 1].set(jnp.log(1.5)))
    j0, j1 = np.asarray(body.joints(p)), np.asarray(body.joints(q))
    par = body.parents[shin]
    assert abs(np.linalg.norm(j1[shin] - j1[par]) / np.linalg.norm(j0[shin] - j0[par]) - 1.5) < 1e-5


def test_unknown_marker_set_or_missing_joint_is_a_clear_error():
    body = toy_skeleton()
    with pytest.raises(ValueError, match="unknown marker set"):
        attach_markers(body, "cmu42")
    with pytest.raises(ValueError, match="no attachment"):
        attach_markers(body, ("C7", "XYZ"))


@pytest.mark.slow
@pytest.mark.skipif(not CMU_01_01.is_file(), reason=f"{CMU_01_01} absent (../shared/data not mounted)")
def test_skeleton_body_reproduces_bvh_forward_kinematics_on_cmu():
    from jaxmotion.formats.bvh import forward_kinematics, read_bvh

    bvh = read_bvh(CMU_01_01)
    body = skeleton_body_from_bvh(bvh, "cmu41", ref_frame=100)
    frames = np.arange(0, 2000, 250)
    params = params_from_bvh(body, bvh, frames)
    joints = np.asarray(jax.vmap(body.joints)(params))
    np.testing.assert_allclose(joints, forward_kinematics(bvh, frames) * 0.056444, atol=1e-4)
    # The reference frame is the zero pose.
    ref = jax.tree.map(lambda a: a[0], params_from_bvh(body, bvh, [100]))
    np.testing.assert_allclose(ref.pose, 0.0, atol=1e-4)


# --------------------------------------------------------------------------------------------
# SMPL-X on a fabricated model file with the real keys and layout.


def _fake_smplx(path: Path, n_v: int = 40, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    weights = rng.random((n_v, NUM_JOINTS)) ** 8
    weights /= weights.sum(1, keepdims=True)
    jreg = rng.random((NUM_JOINTS, n_v))
    jreg /= jreg.sum(1, keepdims=True)
    kin = np.array([[2**32 - 1] + list(SMPLX_PARENTS[1:]), list(range(NUM_JOINTS))], np.int64)
    np.savez(
        path,
        v_template=rng.normal(0, 0.3, (n_v, 3)),
        shapedirs=rng.normal(0, 0.01, (n_v, 3, 20)),
        posedirs=rng.normal(0, 0.003, (n_v, 3, 9 * (NUM_JOINTS - 1))),
        J_regressor=jreg,
        weights=weights,
        kintree_table=kin,
        hands_componentsl=rng.normal(0, 0.2, (45, 45)),
        hands_componentsr=rng.normal(0, 0.2, (45, 45)),
        hands_meanl=rng.normal(0, 0.1, 45),
        hands_meanr=rng.normal(0, 0.1, 45),
        f=np.zeros((1, 3), np.int64),
    )
    return path


def _reference_lbs(path, params, num_betas, n_pca):
    """Full-mesh SMPL-X linear blend skinning in numpy (the smplx package's `lbs`)."""
    d = dict(np.load(path))
    betas, pose, hand = (np.asarray(x, np.float64) for x in (params.shape, params.pose, params.hand))
    v = d["v_template"] + d["shapedirs"][:, :, :num_betas] @ betas
    j = d["J_regressor"] @ v
    hands = [hand[:n_pca] @ d["hands_componentsl"][:n_pca] + d["hands_meanl"],
             hand[n_pca:] @ d["hands_componentsr"][:n_pca] + d["hands_meanr"]]  # fmt: skip
    aa = np.concatenate([pose, np.zeros(9), hands[0], hands[1]]).reshape(-1, 3)
    rots = np.concatenate([np.asarray(rot.rot6d_to_matrix(params.orient))[None], np.asarray(rot.axis_angle_to_matrix(jnp.asarray(aa)))])
    v = v + d["posedirs"] @ (rots[1:] - np.eye(3)).reshape(-1)
    g = np.zeros((NUM_JOINTS, 4, 4))
    for k, p in enumerate(SMPLX_PARENTS):
        local = np.eye(4)
        local[:3, :3] = rots[k]
        local[:3, 3] = j[k] - (j[p] if p >= 0 else 0)
        g[k] = local if p < 0 else g[p] @ local
    a = g.copy()
    a[:, :3, 3] -= np.einsum("kij,kj->ki", g[:, :3, :3], j)
    t = np.einsum("vk,kij->vij", d["weights"], a)
    return np.einsum("vij,vj->vi", t[:, :3, :3], v) + t[:, :3, 3] + np.asarray(params.transl)


@pytest.mark.slow
def test_smplx_marker_skinning_equals_full_mesh_lbs(tmp_path):
    path = _fake_smplx(tmp_path / "SMPLX_NEUTRAL.npz")
    ids = {"C7": 3, "LFHD": 17, "RTOE": 39, "LWRA": 0}
    body = load_smplx(path, ids, num_betas=10, num_pca_comps=6)
    p = body.zero_params()
    assert (p.shape.shape, p.pose.shape, p.hand.shape) == ((10,), (63,), (12,))
    k = jax.random.split(jax.random.key(5), 5)
    p = p._replace(
        transl=jax.random.normal(k[0], (3,)), orient=jax.random.normal(k[1], (6,)),
        shape=jax.random.normal(k[2], (10,)), pose=0.5 * jax.random.normal(k[3], (63,)),
        hand=jax.random.normal(k[4], (12,)),
    )  # fmt: skip
    full = _reference_lbs(path, p, 10, 6)
    np.testing.assert_allclose(body.markers(p), full[list(ids.values())], atol=2e-5)
    assert body.joints(p).shape == (NUM_JOINTS, 3)


def test_smplx_loader_errors_name_the_file_and_key(tmp_path):
    path = _fake_smplx(tmp_path / "m.npz")
    d = dict(np.load(path))
    del d["posedirs"]
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(ValueError, match=r"bad\.npz.*posedirs"):
        load_smplx(tmp_path / "bad.npz", {"a": 0})
    with pytest.raises(ValueError, match="marker_vertices"):
        load_smplx(path, {"a": 40})
    with pytest.raises(FileNotFoundError, match="nothere"):
        load_smplx(tmp_path / "nothere.npz", {"a": 0})


def test_canonical_frame_undoes_heading_and_position():
    from jaxmotion.data.markers import canonicalise

    body = toy_skeleton()
    p = body.zero_params()
    yaw = rot.matrix_to_rot6d(rot.axis_angle_to_matrix(jnp.array([0.0, 2.1, 0.0])))  # about Y (up)
    q = p._replace(orient=yaw, transl=p.transl + jnp.array([3.0, 0.0, -1.0]))
    canon = [canonicalise(np.asarray(body.markers(x))[None], np.asarray(body.joints(x))[None], body.names)[0] for x in (p, q)]
    np.testing.assert_allclose(canon[0], canon[1], atol=1e-5)
    assert len(body.marker_names) == len(canon[0]) > 0
    m = dict(zip(body.marker_names, canon[0]))
    assert m["RFWT"][0] > 0.1 > -0.1 > m["LFWT"][0]  # X: left hip -> right hip
    assert m["STRN"][1] > 0 > m["T10"][1]  # Y forward
    assert m["C7"][2] > 0.3  # Z up, origin at the root


@pytest.mark.slow
def test_analytic_marker_jacobian_equals_autodiff():
    """`SkeletonBody.markers` has a hand-written JVP (what LM fits spend their time on): it must agree
    with plain autodiff for every parameter, the marker offsets and the skeleton, forward and reverse."""
    from jaxmotion.body.skeleton import toy_skeleton

    body = toy_skeleton("bandai")
    k = jax.random.split(jax.random.key(3), 12)
    p = body.zero_params()
    p = p._replace(
        transl=p.transl + jax.random.normal(k[0], (3,)), orient=p.orient + 0.3 * jax.random.normal(k[1], (6,)),
        shape=0.1 * jax.random.normal(k[2], p.shape.shape), pose=0.6 * jax.random.normal(k[3], p.pose.shape),
    )  # fmt: skip
    tp = jax.tree.map(lambda a, kk: jax.random.normal(kk, a.shape), p, type(p)(*k[4:9]))
    tb = body.replace(
        offsets=jax.random.normal(k[10], body.offsets.shape), ref_rot=jax.random.normal(k[11], body.ref_rot.shape),
        marker_offsets=jax.random.normal(k[9], body.marker_offsets.shape),
    )  # fmt: skip
    # Each derivative compiled once (jit): run op by op, the Jacobians took most of this test's time.
    jvp1 = jax.jit(lambda tb_: jax.jvp(lambda b, q: b.markers(q), (body, p), (tb_, tp)))
    jvp2 = jax.jit(lambda tb_: jax.jvp(lambda b, q: b.markers_autodiff(q), (body, p), (tb_, tp)))
    for tangent_body in (tb, jax.tree.map(jnp.zeros_like, tb)):
        (y1, t1), (y2, t2) = jvp1(tangent_body), jvp2(tangent_body)
        np.testing.assert_array_equal(y1, y2)
        np.testing.assert_allclose(t1, t2, atol=2e-5 * float(jnp.abs(t2).max()))
    f1 = lambda q: body.markers(p._replace(pose=q))  # noqa: E731
    f2 = lambda q: body.markers_autodiff(p._replace(pose=q))  # noqa: E731
    jacs = [jax.jit(d(f)) for d in (jax.jacfwd, jax.jacrev) for f in (f1, f2)]
    for pose in (p.pose, jnp.zeros_like(p.pose)):  # the small-angle branch of J_r at zero
        fwd1, fwd2, rev1, rev2 = (j(pose) for j in jacs)
        np.testing.assert_allclose(fwd1, fwd2, atol=1e-5)
        np.testing.assert_allclose(rev1, rev2, atol=1e-5)
