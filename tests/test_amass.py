"""AMASS loader (`jaxmotion.data.amass`) on a fabricated AMASS tree and fabricated SMPL-H / SMPL-X models.

The files have AMASS's real layout (`<root>/<SubDataset>/<Subject>/<seq>_poses.npz`, `poses` (T, 156),
`trans`, `betas` (16,), `mocap_framerate`, `gender`) and the models the real keys, joint counts and
kinematic trees, with 30 vertices.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxmotion.body.markersets import MARKER_SETS
from jaxmotion.data import amass, windows
from jaxmotion.data.amass import SMPL_BODY_PARENTS, load_amass
from jaxmotion.data.datasets import load_dataset
from jaxmotion.errors import DataError

REPO = Path(__file__).resolve().parents[1]
SMPLX_PARENTS = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15,
    20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,
    21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53,
)  # fmt: skip
# SMPL-H: the same 22 body joints, then 15 left-hand joints under joint 20 and 15 right under 21.
SMPLH_PARENTS = SMPL_BODY_PARENTS + tuple(
    w if k % 3 == 0 else base + k - 1 for w, base in ((20, 22), (21, 37)) for k in range(15)
)
N_V = 30

# (folder, subject, file stem, fps, frames, gender). Folder names: today's AMASS names and, for
# BMLrub, HDM05 and Transitions, the first release's (SUBDATASET_ALIASES).
FILES = [
    ("ACCAD", "Female1General_c3d", "A1_-_Stand", 120, 601, "female"),
    ("ACCAD", "Male2General_c3d", "A2_-_Sway", 100, 501, "male"),
    ("BMLhandball", "S01_Expert", "Trial_upper_left_037", 120, 961, "male"),
    ("BioMotionLab_NTroje", "rub001", "0000_treadmill_norm", 120, 300, "female"),
    ("CMU", "01", "01_01", 120, 400, "male"),
    ("CMU", "02", "02_01", 120, 500, "male"),
    ("MPI_HDM05", "bk", "HDM_bk_01-01_01_120", 120, 250, "male"),
    ("HumanEva", "S1", "Box_1", 120, 350, "male"),
    ("DFaust", "50002", "50002_hips", 100, 501, "male"),
    ("Transitions_mocap", "mazen_c3d", "airkick_stand", 120, 601, "female"),
    ("WEIZMANN", "s1", "walk", 120, 200, "male"),  # not in either protocol
]


def fake_model(path: Path, parents: tuple[int, ...], seed: int, pca: bool) -> Path:
    """Writes a body-model npz with the official keys and shapes for `len(parents)` joints."""
    rng = np.random.default_rng(seed)
    n_j = len(parents)
    weights = rng.random((N_V, n_j)) ** 8
    weights /= weights.sum(1, keepdims=True)
    jreg = rng.random((n_j, N_V)) ** 8  # each joint near a few vertices: a body about 1.5 m across, as a person's
    jreg /= jreg.sum(1, keepdims=True)
    extra = {}
    if pca:
        extra = {f"hands_components{s}": rng.normal(0, 0.2, (45, 45)) for s in "lr"}
        extra |= {f"hands_mean{s}": rng.normal(0, 0.1, 45) for s in "lr"}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        v_template=rng.normal(0, 0.3, (N_V, 3)),
        shapedirs=rng.normal(0, 0.01, (N_V, 3, 16)),
        posedirs=rng.normal(0, 0.003, (N_V, 3, 9 * (n_j - 1))),
        J_regressor=jreg,
        weights=weights,
        kintree_table=np.array([[2**32 - 1] + list(parents[1:]), list(range(n_j))], np.int64),
        f=np.zeros((1, 3), np.int64),
        **extra,
    )
    return path


def write_sequence(path: Path, fps: float, t: int, gender: str, seed: int, width: int = 156, rate_key="mocap_framerate"):
    rng = np.random.default_rng(seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        poses=rng.normal(0, 0.2, (t, width)),
        trans=np.cumsum(rng.normal(0, 0.01, (t, 3)), 0) + [0.0, 0.0, 0.9],
        betas=rng.normal(0, 1.0, 16),
        dmpls=np.zeros((t, 8)),
        gender=np.array(gender),
        **{rate_key: np.array(float(fps))},
    )
    return path


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    base = tmp_path_factory.mktemp("amass")
    root = base / "AMASS"
    for i, (sub, subject, stem, fps, t, gender) in enumerate(FILES):
        write_sequence(root / sub / subject / f"{stem}_poses.npz", fps, t, gender, seed=i)
        np.savez(root / sub / subject / "shape.npz", betas=np.zeros(16), gender=np.array(gender))  # no motion: skipped
    smplh = base / "smplh"
    for seed, g in enumerate(("male", "female")):
        fake_model(smplh / g / "model.npz", SMPLH_PARENTS, seed=10 + seed, pca=False)
    smplx = fake_model(base / "smplx" / "SMPLX_NEUTRAL.npz", SMPLX_PARENTS, seed=20, pca=True)
    markers = base / "CMU.json"
    ids = {n: (7 * k) % N_V for k, n in enumerate(MARKER_SETS["cmu41"])}
    markers.write_text(json.dumps({"markersets": [{"distance_from_skin": 0.0095, "indices": ids}]}))
    return {"root": root, "smplh": smplh, "smplx": smplx, "markers": markers, "cache": base / "cache", "ids": ids}


@pytest.fixture(scope="module")
def belfusion(tree):
    return load_amass(tree["root"], "belfusion", tree["smplh"], cache_dir=tree["cache"])


@pytest.fixture(scope="module")
def mojo(tree):
    return load_amass(tree["root"], "mojo", tree["smplx"], marker_vertices=tree["markers"], cache_dir=tree["cache"])


def test_belfusion_split_rates_and_windows(belfusion):
    ds = belfusion
    assert (ds.fps, ds.t_his, ds.t_pred, ds.mm_threshold) == (60.0, 30, 120, 0.4)
    assert ds.skeleton.parents == SMPL_BODY_PARENTS and ds.dim == 63
    assert ds.skeleton.names[:3] == ("pelvis", "left_hip", "right_hip")
    train = sorted(s.name for s in ds.train)
    assert [n.split("/")[0] for n in train] == ["ACCAD", "ACCAD", "BMLhandball", "BioMotionLab_NTroje", "CMU", "CMU"]
    assert sorted(s.name.split("/")[0] for s in ds.test) == ["DFaust", "Transitions_mocap"]
    assert ds.info["subdatasets"] == {"train": ["ACCAD", "BMLhandball", "BMLrub", "CMU"], "test": ["DFaust", "Transitions"]}
    assert ds.info["ignored_folders"] == ["WEIZMANN"]
    # Every 2nd frame from the first: 120 fps 601 -> 301 frames; 100 fps 501 -> 251 (round(100/60) = 2,
    # i.e. 50 fps, as BeLFusion's frame_multiplier).
    by = {s.name: s for s in ds.train + ds.test}
    assert by["ACCAD/Female1General_c3d/A1_-_Stand_poses"].positions.shape == (301, 22, 3)
    assert by["ACCAD/Male2General_c3d/A2_-_Sway_poses"].positions.shape == (251, 22, 3)
    assert by["ACCAD/Male2General_c3d/A2_-_Sway_poses"].fps == 50.0
    assert by["CMU/01/01_01_poses"].subject == "CMU/01" and by["CMU/01/01_01_poses"].action == "01_01"
    assert ds.info["rates"] == {"120->60": 6, "100->50": 2}
    # Test windows every 30 frames, range(0, T - 150, 30): 251 -> 4 (DFaust), 301 -> 6 (Transitions).
    frames = windows.sequence_frames(ds.test)
    w, seq, _ = windows.test_windows(frames, ds.t_his, ds.t_pred)
    assert w.shape == (10, 150, 63)
    assert sorted(np.bincount(seq).tolist()) == [4, 6]


def test_belfusion_validation_subdatasets_join_training_when_asked(tree, belfusion):
    ds = load_amass(tree["root"], "belfusion", tree["smplh"], include_validation=True, cache_dir=tree["cache"])
    assert len(ds.train) == len(belfusion.train) + 2  # HumanEva, HDM05 (folder MPI_HDM05)
    assert ds.info["missing_subdatasets"] == [
        "BMLmovi", "EKUT", "EyesJapanDataset", "KIT", "PosePrior", "TCDHands", "TotalCapture", "SFU", "MoSh",
        "DanceDB", "GRAB", "HUMAN4D", "SOMA", "SSM",
    ]  # fmt: skip


def rodrigues(v: np.ndarray) -> np.ndarray:
    """Rotation matrices of axis-angle vectors `(..., 3)` by the matrix exponential's series (float64)."""
    x, y, z = np.moveaxis(v, -1, 0)
    o = np.zeros_like(x)
    k = np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)
    out, term = np.broadcast_to(np.eye(3), k.shape).copy(), np.broadcast_to(np.eye(3), k.shape).copy()
    for n in range(1, 30):
        term = term @ k / n
        out += term
    return out


def reference_markers(model: Path, ids: list[int], aa: np.ndarray, trans: np.ndarray, betas: np.ndarray) -> np.ndarray:
    """Full-mesh SMPL-X linear blend skinning of one frame in numpy (the smplx package's `lbs`): root and body
    axis-angle `aa` (66,), jaw and eyes zero, hands at the PCA mean (zero coefficients), then vertices `ids`."""
    d = np.load(model)
    v = d["v_template"] + d["shapedirs"][:, :, : len(betas)] @ betas
    j = d["J_regressor"] @ v
    full = np.concatenate([aa, np.zeros(9), d["hands_meanl"], d["hands_meanr"]]).reshape(-1, 3)
    r = rodrigues(full)
    v = v + d["posedirs"] @ (r[1:] - np.eye(3)).reshape(-1)
    g = np.zeros((len(SMPLX_PARENTS), 4, 4))
    for k, p in enumerate(SMPLX_PARENTS):
        local = np.eye(4)
        local[:3, :3], local[:3, 3] = r[k], j[k] - (j[p] if p >= 0 else 0)
        g[k] = local if p < 0 else g[p] @ local
    g[:, :3, 3] -= np.einsum("kij,kj->ki", g[:, :3, :3], j)
    t = np.einsum("vk,kij->vij", d["weights"], g)
    return (np.einsum("vij,vj->vi", t[:, :3, :3], v) + t[:, :3, 3] + trans)[ids]


def reference_joints(model: Path, poses: np.ndarray, trans: np.ndarray, betas: np.ndarray) -> np.ndarray:
    """SMPL-H body joints 0-21 in float64 numpy (human_body_prior's `Jtr[:, :22]`): rest joints, then FK."""
    d = np.load(model)
    rest = d["J_regressor"] @ (d["v_template"] + d["shapedirs"][:, :, : len(betas)] @ betas)
    r = rodrigues(poses[:, :66].reshape(len(poses), 22, 3))
    g_r, g_t = np.zeros((len(poses), 22, 3, 3)), np.zeros((len(poses), 22, 3))
    for j, p in enumerate(SMPL_BODY_PARENTS):
        if p < 0:
            g_r[:, j], g_t[:, j] = r[:, j], rest[j]
        else:
            g_r[:, j] = g_r[:, p] @ r[:, j]
            g_t[:, j] = g_t[:, p] + g_r[:, p] @ (rest[j] - rest[p])
    return g_t + trans[:, None]


def test_smplh_model_file_loads_as_a_52_joint_body(tree):
    """`load_smplx` on an SMPL-H npz (no jaw / eyes, full axis-angle hands): `body.joints` under jit against numpy."""
    import jax

    from jaxmotion.body.params import BodyParams
    from jaxmotion.body.rotation import axis_angle_to_matrix, matrix_to_rot6d
    from jaxmotion.body.smplx import load_smplx

    model = tree["smplh"] / "male" / "model.npz"
    body = load_smplx(model, {}, num_betas=16, num_pca_comps=0, flat_hand_mean=True)
    assert (body.num_joints, body.parents, body.marker_names) == (52, SMPLH_PARENTS, ())
    rng = np.random.default_rng(7)
    poses, trans, betas = rng.normal(0, 0.4, (3, 156)), rng.normal(0, 1, (3, 3)), rng.normal(0, 1, 16)

    def joints(aa, t):
        p = BodyParams(t, matrix_to_rot6d(axis_angle_to_matrix(aa[:3])), jax.numpy.asarray(betas, "float32"), aa[3:66], aa[66:])
        return body.joints(p)

    one = jax.jit(joints)  # a single-frame function compiles in about half the time of its vmap
    got = np.stack([one(a, t) for a, t in zip(poses.astype(np.float32), trans.astype(np.float32))])
    assert got.shape == (3, 52, 3)
    np.testing.assert_allclose(got[:, :22], reference_joints(model, poses, trans, betas), atol=2e-5)


def test_belfusion_joints_are_the_gendered_smplh_joints(tree, belfusion):
    ds = belfusion
    seq = next(s for s in ds.test if s.name.startswith("Transitions"))  # female, 120 fps
    f = np.load(tree["root"] / f"{seq.name}.npz")
    want = reference_joints(tree["smplh"] / "female" / "model.npz", f["poses"][::2], f["trans"][::2], f["betas"])
    np.testing.assert_allclose(seq.positions, want, atol=2e-5)
    other = reference_joints(tree["smplh"] / "male" / "model.npz", f["poses"][::2], f["trans"][::2], f["betas"])
    assert np.abs(seq.positions - other).max() > 1e-3  # the male model would give other joints


def test_zero_pose_and_translation_give_the_rest_joints(tree, tmp_path):
    root = tmp_path / "AMASS"
    for sub, t in (("CMU", 5), ("SSM_synced", 7)):
        p = write_sequence(root / sub / "s" / "zero_poses.npz", 120, t, "female", seed=0)
        d = dict(np.load(p))
        np.savez(p, **(d | {"poses": np.zeros_like(d["poses"]), "trans": np.zeros_like(d["trans"])}))
    ds = load_amass(root, "belfusion", tree["smplh"], cache_dir=tmp_path / "cache")
    m = np.load(tree["smplh"] / "female" / "model.npz")
    for s in ds.train + ds.test:
        rest = m["J_regressor"] @ (m["v_template"] + m["shapedirs"] @ np.load(root / f"{s.name}.npz")["betas"])
        np.testing.assert_allclose(s.positions, np.broadcast_to(rest[:22], s.positions.shape), atol=1e-5)
    assert [len(s.positions) for s in ds.train + ds.test] == [3, 4]


def test_mojo_split_rates_markers_and_windows(tree, mojo):
    ds = mojo
    assert (ds.fps, ds.t_his, ds.t_pred, ds.mm_threshold) == (15.0, 15, 45, 0.5)
    assert ds.info["frames"] == "global" and ds.info["up_axis"] == 2 and ds.info["marker_set"] == "CMU"
    assert ds.info["point_names"] == tuple(MARKER_SETS["cmu41"]) and ds.dim == 123
    assert sorted(s.name.split("/")[0] for s in ds.train) == ["CMU", "CMU", "MPI_HDM05"]
    assert sorted(s.name.split("/")[0] for s in ds.test) == ["ACCAD", "ACCAD", "BMLhandball"]
    # Every 8th frame at 120 fps (MOJO's sample_rate=8): 601 -> 76, 961 -> 121; 100 fps: every 7th, 501 -> 72.
    by = {s.name.split("/")[0] + str(s.fps): s for s in ds.test}
    assert by["ACCAD15.0"].positions.shape == (76, 41, 3) and by["BMLhandball15.0"].positions.shape == (121, 41, 3)
    assert by[f"ACCAD{100 / 7}"].positions.shape == (72, 41, 3)
    # range(0, T - 60, 15): 76 -> 2, 121 -> 5, 72 -> 1.
    frames, canon = windows.split_frames(ds, "test")
    w, seq, starts = windows.test_windows(frames, ds.t_his, ds.t_pred)
    assert w.shape == (8, 60, 123) and sorted(np.bincount(seq).tolist()) == [1, 2, 5]
    # The markers are the SMPL-X marker vertices with betas[:10], the file's root and body pose, mean hands.
    s = by["BMLhandball15.0"]
    f = np.load(tree["root"] / f"{s.name}.npz")
    for i in (0, 40, 120):
        want = reference_markers(tree["smplx"], list(tree["ids"].values()), f["poses"][8 * i, :66], f["trans"][8 * i], f["betas"][:10])
        np.testing.assert_allclose(s.positions[i], want, atol=3e-5)


def test_numpy_joints_equal_the_body_models_joints(tree, mojo):
    """`amass.body_joints` (numpy, the BeLFusion protocol) against `SmplxBody.joints` under jit (the MOJO path)."""
    body = mojo.info["body"]
    f = np.load(Path(mojo.info["source"]) / "ACCAD/Female1General_c3d/A1_-_Stand_poses.npz")
    poses, trans, betas = (f[k].astype(np.float32) for k in ("poses", "trans", "betas"))
    jax_joints, _ = amass.sequence_points(body, poses[:100], trans[:100], betas[:10])
    np.testing.assert_allclose(amass.body_joints(body, poses[:100], trans[:100], betas[:10]), jax_joints, atol=3e-5)


def test_mojo_canonical_frame_is_mojos_parameter_transform(mojo):
    """MOJO canonicalises the SMPL-X parameters (orient <- M^T orient, trans <- M^T (trans - trans_0)), then
    re-runs the body; `canon` must give the same markers from the global ones."""
    ds = mojo
    body = ds.info["body"]
    s = next(s for s in ds.test if s.name.startswith("BMLhandball"))
    t0 = 30
    f = np.load(Path(ds.info["source"]) / f"{s.name}.npz")
    poses, trans, betas = f["poses"][::8][t0 : t0 + 60], f["trans"][::8][t0 : t0 + 60], f["betas"][:10]
    got = windows.canonicalise_windows(s.positions[t0 : t0 + 60].reshape(1, 60, -1), s.canon[t0][None])[0]

    joints, _ = amass.sequence_points(body, poses.astype(np.float32), trans.astype(np.float32), betas.astype(np.float32))
    x = joints[0, 2] - joints[0, 1]
    x[2] = 0
    x /= np.linalg.norm(x)
    m = np.stack([x, np.cross([0, 0, 1.0], x), [0, 0, 1.0]], axis=1)  # MOJO's transf_rotmat (columns)
    orient = Rotation.from_matrix(m.T @ Rotation.from_rotvec(poses[:, :3]).as_matrix()).as_rotvec()
    new_poses = np.concatenate([orient, poses[:, 3:]], axis=1).astype(np.float32)
    new_trans = ((trans - trans[0]) @ m).astype(np.float32)  # M^T (trans - trans_0), row-wise
    _, want = amass.sequence_points(body, new_poses, new_trans, betas.astype(np.float32))
    np.testing.assert_allclose(got.reshape(want.shape), want, atol=5e-5)
    # MOJO's frame: at the window's first frame the hips are on the X axis, Z stays up.
    hips = windows.canonicalise_windows(joints[None, :, 1:3].reshape(1, 60, 6), s.canon[t0][None])[0].reshape(60, 2, 3)
    assert abs(hips[0, 1, 1] - hips[0, 0, 1]) < 1e-5 and hips[0, 1, 0] > hips[0, 0, 0]


def test_cache_is_reused_and_keyed_by_files_and_model(tree, tmp_path, monkeypatch):
    root = tmp_path / "AMASS"
    for sub in ("CMU", "DFaust"):
        write_sequence(root / sub / "s" / "a_poses.npz", 120, 200, "male", seed=3)
    cache = tmp_path / "cache"
    first = load_amass(root, "belfusion", tree["smplh"], cache_dir=cache)
    assert len(list(cache.glob("belfusion_*.npz"))) == 2

    def fail(*a, **k):
        raise AssertionError("recomputed")

    monkeypatch.setattr(amass, "_compute_subset", fail)
    again = load_amass(root, "belfusion", tree["smplh"], cache_dir=cache)  # both sub-datasets from the cache
    np.testing.assert_array_equal(again.test[0].positions, first.test[0].positions)
    write_sequence(root / "DFaust" / "s" / "a_poses.npz", 120, 210, "male", seed=4)
    with pytest.raises(AssertionError, match="recomputed"):
        load_amass(root, "belfusion", tree["smplh"], cache_dir=cache)
    monkeypatch.undo()
    other_model = tmp_path / "smplh"
    for g in ("male", "female"):
        fake_model(other_model / g / "model.npz", SMPLH_PARENTS, seed=30, pca=False)
    moved = load_amass(root, "belfusion", other_model, cache_dir=cache)
    assert np.abs(moved.train[0].positions - first.train[0].positions).max() > 1e-3


def test_load_dataset_finds_amass_by_prefix_and_by_folder(tree, belfusion):
    opts = {"protocol": "belfusion", "model_path": tree["smplh"], "cache_dir": tree["cache"]}
    for spec in (f"amass:{tree['root']}", tree["root"]):
        ds = load_dataset(spec, **opts)
        assert ds.name == "amass_belfusion" and len(ds.train) == len(belfusion.train) and len(ds.test) == 2


def test_smplx_files_need_an_smplx_model(tree, tmp_path):
    root = tmp_path / "AMASS"
    for sub in ("CMU", "GRAB"):  # SMPL-X G layout: *_stageii.npz, poses (T, 165), mocap_frame_rate
        write_sequence(root / sub / "s1" / "a_stageii.npz", 120, 100, "neutral", 0, width=165, rate_key="mocap_frame_rate")
        np.savez(root / sub / "s1" / "neutral_stagei.npz", betas=np.zeros(16))
    ds = load_amass(root, "belfusion", tree["smplx"], cache_dir=tmp_path / "c")
    assert [s.positions.shape for s in ds.train + ds.test] == [(50, 22, 3), (50, 22, 3)]
    with pytest.raises(DataError, match=r"a_stageii\.npz: needs an SMPL-X model .*SMPL-H \(52 joints\)"):
        load_amass(root, "belfusion", tree["smplh"] / "male" / "model.npz", cache_dir=tmp_path / "c")


def test_errors_name_the_problem(tree, tmp_path):
    with pytest.raises(ValueError, match="model_path is required.*mano.is.tue.mpg.de.*smpl-x.is.tue.mpg.de"):
        load_amass(tree["root"], "belfusion")
    with pytest.raises(FileNotFoundError, match="nothere.*mano.is.tue.mpg.de"):
        load_amass(tree["root"], "belfusion", tmp_path / "nothere")
    with pytest.raises(ValueError, match="marker_vertices.*MOJO-release"):
        load_amass(tree["root"], "mojo", tree["smplx"])
    with pytest.raises(DataError, match="needs an SMPL-X model .*MOJO's markers are SMPL-X vertices"):
        load_amass(tree["root"], "mojo", tree["smplh"], marker_vertices=tree["ids"], cache_dir=tmp_path / "c")
    with pytest.raises(ValueError, match="protocol must be one of"):
        load_amass(tree["root"], "dlow", tree["smplh"])

    root = tmp_path / "AMASS"
    good = write_sequence(root / "CMU" / "01" / "01_01_poses.npz", 120, 50, "male", 0)
    bad = write_sequence(root / "SSM" / "s" / "x_poses.npz", 120, 50, "male", 1, width=72)
    with pytest.raises(DataError, match=r"x_poses\.npz: poses has shape \(50, 72\), expected \(T, 156\)"):
        load_amass(root, "belfusion", tree["smplh"], cache_dir=tmp_path / "c")
    d = dict(np.load(good))
    d["poses"][7, 4] = np.nan
    np.savez(bad, **d)
    with pytest.raises(DataError, match=r"x_poses\.npz: poses \(frame, joint\): non-finite value nan at frame 7, joint 1"):
        load_amass(root, "belfusion", tree["smplh"], cache_dir=tmp_path / "c")
    with pytest.raises(DataError, match="no test sequence"):  # MOJO's skip: the only test file goes
        load_amass(root, "belfusion", tree["smplh"], skip_nonfinite=True, cache_dir=tmp_path / "c")
    np.savez(bad, **(d | {"gender": np.array("neutral"), "poses": np.zeros_like(d["poses"])}))
    with pytest.raises(FileNotFoundError, match=r"no neutral body model \(tried .*neutral/model\.npz"):
        load_amass(root, "belfusion", tree["smplh"], cache_dir=tmp_path / "c")


@pytest.mark.parametrize("name, protocol", [("dlow_amass", "belfusion"), ("mojo_amass", "mojo")])
def test_configs(name, protocol):
    from jaxmotion.config import load_config

    path = REPO / "experiments" / "configs" / f"{name}.py"
    cfg = load_config(path)
    assert cfg.dataset.startswith("amass:") and cfg.data_options["protocol"] == protocol
    top = path.read_text().splitlines()[0]
    assert top.startswith(f"# jaxmotion run --config experiments/configs/{name}.py --data amass:")
    assert "licensed" in path.read_text()[:1500]
