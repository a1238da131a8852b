"""AMASS under two protocols ([protocol §4][datasets]): BeLFusion's 22 SMPL-H joints and MOJO's SMPL-X markers.

    ds = load_amass("~/data/AMASS", "belfusion", model_path="~/body_models/smplh")   # <gender>/model.npz
    ds = load_amass("~/data/AMASS", "mojo", model_path="~/body_models/smplx", marker_vertices="CMU.json")
    ds = load_dataset("amass:~/data/AMASS", protocol="mojo", ...)                     # the same, by spec

AMASS (amass.is.tue.mpg.de, free registration, licensed, not shipped) is one archive per
sub-dataset; extracted they give `<root>/<SubDataset>/<Subject>/<seq>_poses.npz` (SMPL-H G) or
`<seq>_stageii.npz` (SMPL-X G/N). A sequence file holds `poses` (T, 156) axis-angle: root, 21
body joints, 15 + 15 hand joints (SMPL-X files: (T, 165), with jaw and eyes between body and
hands), `trans` (T, 3), `betas` (16,), `mocap_framerate` (`mocap_frame_rate` in SMPL-X files) and
`gender`; AMASS's world is Z up. Subject folders also hold `shape.npz` / `*_stagei.npz` (no
motion), which are skipped. Sub-dataset folders may carry the current download names (BeLFusion's
lists, below) or the older release's names (`SUBDATASET_ALIASES`: `BioMotionLab_NTroje` = BMLrub,
`MPI_HDM05` = HDM05, `SSM_synced` = SSM, ...).

Positions come from the body model the files were fitted with, which the user supplies
(`model_path`: one npz for every sequence, or a folder with `<gender>/model.npz` (MANO's SMPL-H
layout) or `SMPLX_<GENDER>.npz` / `SMPLH_<GENDER>.npz`, chosen by each file's `gender`), loaded by
`jaxmotion.body.smplx.load_smplx`: markers are `SmplxBody.markers` under jit; the 22 joints of the
joint protocol are the same forward kinematics in numpy (`body_joints`, tested against
`SmplxBody.joints`), which spares an XLA compilation per body model. Both protocols keep every `s`-th frame from the first, with
`s = int(np.round(mocap_framerate / fps))`, as BeLFusion's `frame_multiplier` and MOJO's
`sample_rate=8` at 120 fps do (no interpolation): 120 -> 60 fps keeps `ceil(T / 2)` frames,
120 -> 15 fps `ceil(T / 8)`, and 100 fps also takes every 2nd frame (`round(1.67) = 2`), i.e.
50 fps labelled 60 as in BeLFusion's preprocessing (`Sequence.fps` records the true 50). A file
whose rate rounds to `s = 0` (under half the protocol's rate) is skipped, as BeLFusion's
`[::0]` error skips it.

- `protocol="belfusion"` (BeLFusion, Barquero et al. 2023, `data_loader/parsers/amass.py` and
  `data_loader/amass.py`): the first 22 joints of SMPL-H (pelvis and 21 body joints; gendered
  models, 16 betas, full poses), 60 fps, 30 -> 120 frames, MM threshold 0.4, root-relative with
  the pelvis dropped (`windows.to_frames`, D = 63). Train: `BELFUSION_SPLIT["train"]`, test:
  `["test"]`; BeLFusion's validation sub-datasets (HumanEva HDM05 SFU MoSh) are left out unless
  `include_validation=True` (its released AMASS model trained on train + validation). SMPL-H G
  files need an SMPL-H model, SMPL-X files an SMPL-X model.
- `protocol="mojo"` (MOJO, Zhang et al. 2021, `experiments/utils/utils_canonicalize_amass.py`):
  SMPL-X markers (vertex ids from `marker_vertices`: MOJO's `CMU.json`, 41 markers, or `SSM2.json`,
  67) of the SMPL-X body driven by the file's root and 21 body joints (`poses[:, :66]`, SMPL-H G
  files as MOJO did; hands at the PCA mean, jaw and eyes zero) with `betas[:10]`, 15 fps,
  15 -> 45 frames, MM threshold 0.5; train CMU, HDM05 / test ACCAD, BMLhandball (`MOJO_SPLIT`).
  Frames are global markers, each window canonicalised at its first frame ([protocol §5][marker-canonicalisation]):
  X from the left to the right hip on the ground, Z up, Y = Z x X. MOJO applies this to the
  SMPL-X parameters (global orientation, `trans`), which rotates the body about the pelvis, not
  about `trans`: a point moves to `R (p - pelvis_0) + j0` with `j0 = pelvis - trans` (the rest
  pelvis, constant per sequence); `Sequence.canon`'s origin is set so `R (p - o)` is exactly that.

Deviations from the references, on purpose: test windows start every `t_his` frames of each whole
sequence ([protocol §4][datasets]); BeLFusion evaluates fixed segments (`segments_test.csv`: predictions
from frame 180 every 120 frames) and MOJO one window per non-overlapping 4 s chunk (480 frames at
120 fps; sequences under 4 s are dropped), which are every 4th of these windows. A NaN/inf in
`poses`, `trans` or `betas` is a `DataError` (MOJO skips such files: `skip_nonfinite=True`).

Joint / marker positions are computed once per sub-dataset and cached in `cache_dir` (default
`~/.cache/jaxmotion/amass`, beside `bandai.default_cache_dir()`), keyed by protocol, options,
each file's path, size and mtime, and the model file(s) and marker ids.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.body.params import BodyParams
from jaxmotion.body.rotation import axis_angle_to_matrix, matrix_to_rot6d
from jaxmotion.body.smplx import NUM_JOINTS, SMPLH_NUM_JOINTS, SmplxBody, load_smplx
from jaxmotion.data.augment import left_right_pairs
from jaxmotion.data.bandai import default_cache_dir
from jaxmotion.data.markers import marker_skeleton
from jaxmotion.data.plausible import check_positions
from jaxmotion.data.types import MotionDataset, Sequence, Skeleton, check_finite
from jaxmotion.errors import DataError
from jaxmotion.formats.atomic import savez_atomic
from jaxmotion.formats.npz import read_arrays

# BeLFusion's lists (`data_loader/amass.py`, its released AMASS config), AMASS's current names.
BELFUSION_SPLIT = {
    "train": ("ACCAD", "BMLhandball", "BMLmovi", "BMLrub", "CMU", "EKUT", "EyesJapanDataset", "KIT",
              "PosePrior", "TCDHands", "TotalCapture"),
    "validation": ("HumanEva", "HDM05", "SFU", "MoSh"),
    "test": ("DFaust", "DanceDB", "GRAB", "HUMAN4D", "SOMA", "SSM", "Transitions"),
}  # fmt: skip
MOJO_SPLIT = {"train": ("CMU", "HDM05"), "test": ("ACCAD", "BMLhandball")}
# The first AMASS release's folder names (MOJO's `MPI_HDM05`, DLow-era code) for today's names.
SUBDATASET_ALIASES = {
    "BMLrub": ("BioMotionLab_NTroje",), "DFaust": ("DFaust_67",), "EyesJapanDataset": ("Eyes_Japan_Dataset",),
    "PosePrior": ("MPI_Limits",), "TCDHands": ("TCD_handMocap",), "HDM05": ("MPI_HDM05",), "MoSh": ("MPI_mosh",),
    "SSM": ("SSM_synced",), "Transitions": ("Transitions_mocap",),
}  # fmt: skip
PROTOCOLS = {
    "belfusion": {"fps": 60.0, "t_his": 30, "t_pred": 120, "mm_threshold": 0.4},
    "mojo": {"fps": 15.0, "t_his": 15, "t_pred": 45, "mm_threshold": 0.5},
}
NUM_BETAS = {"belfusion": 16, "mojo": 10}  # BeLFusion's `num_betas = 16`; MOJO's `betas[:10]`
SEQUENCE_SUFFIXES = ("_poses.npz", "_stageii.npz")
POSES_WIDTH = {156: "smplh", 165: "smplx"}  # 52 x 3 (SMPL-H G), 55 x 3 (SMPL-X G / N)

# SMPL-H / SMPL-X joints 0-21 (smplx.joint_names), and their parents in both models.
SMPL_BODY_JOINT_NAMES = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)  # fmt: skip
SMPL_BODY_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

MODEL_HELP = (
    "AMASS positions need the body model the files were fitted with (licensed, not shipped): SMPL-H for "
    "AMASS's SMPL-H G files and BeLFusion's protocol (mano.is.tue.mpg.de, Downloads, 'Extended SMPL+H model': "
    "a folder with male/ female/ neutral/model.npz), SMPL-X for SMPL-X G files and MOJO's markers "
    "(smpl-x.is.tue.mpg.de: SMPLX_NEUTRAL.npz, SMPLX_MALE.npz, SMPLX_FEMALE.npz). Pass model_path= one "
    "npz, or a folder of gendered models (data_options={'model_path': ...} in a config)"
)
MARKER_HELP = (
    "MOJO's markers are SMPL-X vertex ids: pass marker_vertices= a {name: vertex} dict or a MoSh marker-set "
    "JSON ({'markersets': [{'indices': {name: vertex}}]}), MOJO's CMU.json (41 markers) or SSM2.json (67), "
    "linked from the README of github.com/yz-cnsdqz/MOJO-release"
)
_CACHE_VERSION = 1
_CHUNK = 512  # frames per jitted call: one compilation for every sequence length


@dataclasses.dataclass
class AmassFile:
    """One AMASS sequence file, read and checked (`read_amass_file`)."""

    poses: np.ndarray  # (T, 156) SMPL-H or (T, 165) SMPL-X, axis-angle
    trans: np.ndarray  # (T, 3)
    betas: np.ndarray  # (B,)
    fps: float
    gender: str
    model_type: str  # "smplh" or "smplx", from the width of `poses`


def read_amass_file(path: str | os.PathLike, skip_nonfinite: bool = False) -> AmassFile | None:
    """Returns the checked content of an AMASS npz, or raises `DataError` naming the file and key.

    Checks the keys, `poses` (T, 156 | 165), `trans` (T, 3), `betas` (1-D), a positive frame rate,
    and that all three arrays are finite (the first bad frame is named; `skip_nonfinite`: None instead).
    """
    path = Path(path)
    # Only the keys used: SMPL-X stage-ii files also hold pickled marker-to-vertex dicts, which are never unpickled.
    data = read_arrays(path, ("poses", "trans", "betas", "mocap_framerate", "mocap_frame_rate", "gender"), what="AMASS sequence")
    rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in data), None)
    missing = [k for k in ("poses", "trans", "betas") if k not in data] + ([] if rate_key else ["mocap_framerate"])
    if missing:
        raise DataError(path, f"missing keys {missing} (an AMASS sequence has poses, trans, betas, mocap_framerate; has {sorted(data)})")
    poses, trans, betas = data["poses"], data["trans"], data["betas"]
    for key, arr in (("poses", poses), ("trans", trans), ("betas", betas), (rate_key, data[rate_key])):
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise DataError(path, f"{key} must hold real numbers, got dtype {arr.dtype}")
    if poses.ndim != 2 or poses.shape[1] not in POSES_WIDTH:
        raise DataError(
            path, f"poses has shape {poses.shape}, expected (T, 156) (SMPL-H G: 52 joints x 3 axis-angle) or "
            "(T, 165) (SMPL-X: 55 x 3); other AMASS variants (SMPL: 72, DMPL) are not supported"
        )  # fmt: skip
    if poses.shape[0] == 0:
        raise DataError(path, "poses has no frames")
    if trans.shape != (poses.shape[0], 3):
        raise DataError(path, f"trans has shape {trans.shape}, expected ({poses.shape[0]}, 3) (one per frame of poses)")
    if betas.ndim != 1:
        raise DataError(path, f"betas has shape {betas.shape}, expected (B,)")
    rate = np.asarray(data[rate_key], np.float64).reshape(-1)
    if rate.size != 1 or not np.isfinite(rate[0]) or rate[0] <= 0:
        raise DataError(path, f"{rate_key} must be one positive number, got {data[rate_key]!r}")
    with np.errstate(over="ignore"):
        poses, trans, betas = (np.asarray(a, np.float32) for a in (poses, trans, betas))
    if skip_nonfinite and not all(np.isfinite(a).all() for a in (poses, trans, betas)):
        return None
    check_finite(path, poses.reshape(len(poses), -1, 3), "poses (frame, joint)")
    check_finite(path, trans[:, None], "trans")
    if not np.isfinite(betas).all():
        raise DataError(path, f"betas: non-finite value at index {int(np.argmin(np.isfinite(betas)))} ({betas.tolist()})")
    return AmassFile(poses, trans, betas, float(rate[0]), _gender(data.get("gender")), POSES_WIDTH[poses.shape[1]])


def _gender(value) -> str:
    """Returns `male` / `female` / `neutral` from a file's `gender` (str, bytes, or a str of bytes as in SSM)."""
    if value is None:
        return "neutral"
    g = np.asarray(value).reshape(-1)[0] if np.asarray(value).size else "neutral"
    g = g.decode() if isinstance(g, bytes) else str(g)
    g = g.strip().lower()
    if g.startswith(("b'", 'b"')):
        g = g[2:-1]
    return g


def frame_stride(mocap_fps: float, fps: float) -> int:
    """Returns the frame step taking `mocap_fps` to about `fps`: `int(np.round(mocap_fps / fps))` (BeLFusion).

    0 (a rate under half of `fps`) means the file cannot be brought to `fps` by keeping frames.
    """
    return int(np.round(mocap_fps / fps))


def find_sequences(root: str | os.PathLike) -> tuple[dict[str, list[Path]], list[str]]:
    """Returns `({sub-dataset: sorted sequence files}, [folders of no known sub-dataset])` under `root`.

    Sub-datasets are named by `BELFUSION_SPLIT` / `MOJO_SPLIT` (the folder may use an alias of
    `SUBDATASET_ALIASES`); sequence files end in `_poses.npz` or `_stageii.npz`, at any depth.
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: no such folder (expected AMASS sub-dataset folders: ACCAD/, CMU/, ...)")
    known = {n for split in (BELFUSION_SPLIT, MOJO_SPLIT) for names in split.values() for n in names}
    by_folder = {n: n for n in known} | {a: n for n, aliases in SUBDATASET_ALIASES.items() for a in aliases}
    found: dict[str, list[Path]] = {}
    folders: dict[str, str] = {}
    unknown = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        name = by_folder.get(d.name)
        if name is None:
            unknown.append(d.name)
            continue
        if name in folders:
            raise DataError(root, f"sub-dataset {name} is there twice: folders {folders[name]!r} and {d.name!r}")
        folders[name] = d.name
        found[name] = sorted(p for p in d.rglob("*.npz") if p.name.endswith(SEQUENCE_SUFFIXES))
    return found, unknown


def is_amass_root(path: str | os.PathLike) -> bool:
    """Returns whether `path` is a folder holding at least one AMASS sub-dataset folder with a sequence file."""
    path = Path(path)
    if not path.is_dir():
        return False
    found, _ = find_sequences(path)
    return any(found.values())


def model_file(model_path: Path, gender: str) -> Path:
    """Returns the model npz for `gender`: `model_path` itself if a file, else the gendered file in that folder."""
    if model_path.is_file():
        return model_path
    tried = [model_path / gender / "model.npz", model_path / f"SMPLX_{gender.upper()}.npz", model_path / f"SMPLH_{gender.upper()}.npz"]
    for p in tried:
        if p.is_file():
            return p
    raise FileNotFoundError(f"{model_path}: no {gender} body model (tried {[str(p) for p in tried]}). {MODEL_HELP}")


def read_marker_vertices(marker_vertices) -> tuple[str, dict[str, int]]:
    """Returns `(marker set name, {marker: vertex})` from a dict or a MoSh / MOJO marker-set JSON file."""
    if marker_vertices is None:
        raise ValueError(f"load_amass(protocol='mojo') needs marker_vertices. {MARKER_HELP}")
    if isinstance(marker_vertices, dict):
        name, ids = "custom", marker_vertices
    else:
        path = Path(marker_vertices).expanduser()
        if not path.is_file():
            raise FileNotFoundError(f"{path}: marker-set file not found. {MARKER_HELP}")
        try:
            data = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError) as e:
            raise DataError(path, f"not a JSON marker set ({type(e).__name__}: {e})") from None
        if isinstance(data, dict) and isinstance(data.get("markersets"), list) and data["markersets"]:
            data = data["markersets"][0].get("indices")
        name, ids = path.stem, data
    if not isinstance(ids, dict) or not ids or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in ids.values()):
        raise DataError(str(marker_vertices), f"marker vertices must be a non-empty {{name: vertex id}} mapping. {MARKER_HELP}")
    return name, {str(k): int(v) for k, v in ids.items()}


def _model_joint_count(path: Path) -> int:
    """Returns the joint count of a model npz (52 SMPL-H, 55 SMPL-X) from its `kintree_table`, reading only that."""
    kin = read_arrays(path, ("kintree_table",), what="SMPL-X / SMPL-H model", required=("kintree_table",))["kintree_table"]
    return int(kin.shape[1]) if kin.ndim == 2 else -1


def body_joints(body: SmplxBody, poses: np.ndarray, trans: np.ndarray, betas: np.ndarray) -> np.ndarray:
    """Returns `(T, 22, 3)` float32: `body.joints` 0-21 at each frame's root + body axis-angle `poses[:, :66]`.

    The same forward kinematics over the body's regressed rest joints (`J_reg (v_template + S betas)`),
    in float64 numpy: a preprocessing step run once per file, which would otherwise cost an XLA
    compilation of several seconds per body model. `tests/test_amass.py` checks it against `body.joints`.
    """
    rest = np.asarray(body.j_template, np.float64) + np.einsum("jdb,b->jd", np.asarray(body.j_shapedirs, np.float64), betas)
    v = np.asarray(poses[:, :66], np.float64).reshape(len(poses), 22, 3)
    angle = np.linalg.norm(v, axis=-1)[..., None, None]
    x, y, z = np.moveaxis(v / np.maximum(angle[..., 0], 1e-12), -1, 0)
    o = np.zeros_like(x)
    k = np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)
    local = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)  # Rodrigues
    g_r, g_t = np.empty_like(local), np.empty((len(poses), 22, 3))
    for j, p in enumerate(SMPL_BODY_PARENTS):
        if p < 0:
            g_r[:, j], g_t[:, j] = local[:, j], rest[j]
        else:
            g_r[:, j] = g_r[:, p] @ local[:, j]
            g_t[:, j] = g_t[:, p] + g_r[:, p] @ (rest[j] - rest[p])
    return (g_t + trans[:, None]).astype(np.float32)


@jax.jit
def _body_points(body: SmplxBody, poses, trans, betas):
    """Returns `(joints (n, 22, 3), markers (n, M, 3))` of the body at each frame's root + body axis-angle `poses[:, :66]`."""

    def frame(aa, t):
        p = BodyParams(
            transl=t,
            orient=matrix_to_rot6d(axis_angle_to_matrix(aa[:3])),
            shape=betas,
            pose=aa[3:66],
            hand=jnp.zeros(body.num_hand, aa.dtype),  # PCA mean (MOJO) or flat; no body joint depends on it
        )
        return body.joints(p)[: len(SMPL_BODY_PARENTS)], body.markers(p)

    return jax.vmap(frame)(poses, trans)


def sequence_points(body: SmplxBody, poses: np.ndarray, trans: np.ndarray, betas: np.ndarray):
    """Returns `(joints (T, 22, 3), markers (T, M, 3))` float32 of a whole sequence (`body.joints`, `body.markers`
    under jit, in fixed-size chunks: one compilation for every length)."""
    joints, markers = [], []
    for s in range(0, len(poses), _CHUNK):
        p, t = poses[s : s + _CHUNK, :66], trans[s : s + _CHUNK]
        n = len(p)
        if n < _CHUNK:
            p, t = (np.concatenate([a, np.repeat(a[-1:], _CHUNK - n, 0)]) for a in (p, t))
        j, m = _body_points(body, jnp.asarray(p), jnp.asarray(t), jnp.asarray(betas))
        joints.append(np.asarray(j)[:n])
        markers.append(np.asarray(m)[:n])
    return np.concatenate(joints), np.concatenate(markers)


def mojo_canon(joints: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Returns `(T, 4, 3)`: at each frame MOJO's canonical frame, rows R then origin o (`p' = R (p - o)`).

    R's rows: X from left hip (joint 1) to right hip (joint 2) with Z set to 0, Z = (0, 0, 1), Y = Z x X
    (`get_new_coordinate`). MOJO rotates the global orientation and translates `trans`, so the body turns
    about its pelvis: `p' = R (p - pelvis) + j0`, `j0 = pelvis - trans`; that is `o = pelvis - R^T j0`.
    """
    x = joints[:, 2] - joints[:, 1]
    x[:, 2] = 0.0
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    z = np.broadcast_to(np.array([0.0, 0.0, 1.0], x.dtype), x.shape)
    r = np.stack([x, np.cross(z, x), z], axis=1)
    j0 = joints[:, 0] - trans
    origin = joints[:, 0] - np.einsum("tij,ti->tj", r, j0)
    return np.concatenate([r, origin[:, None]], axis=1).astype(np.float32)


def load_amass(
    root: str | os.PathLike,
    protocol: str = "belfusion",
    model_path: str | os.PathLike | None = None,
    *,
    marker_vertices: dict[str, int] | str | os.PathLike | None = None,
    include_validation: bool = False,
    test_subsets: tuple[str, ...] | list[str] | None = None,
    num_betas: int | None = None,
    skip_nonfinite: bool = False,
    cache_dir: str | os.PathLike | None = None,
) -> MotionDataset:
    """Returns AMASS as a `MotionDataset` under `protocol` "belfusion" (22 joints) or "mojo" (markers).

    `model_path`: the SMPL-H / SMPL-X model npz, or a folder of gendered ones (module docstring).
    `marker_vertices` (mojo): `{name: SMPL-X vertex}` or MOJO's `CMU.json` / `SSM2.json`.
    `include_validation` (belfusion): train on BeLFusion's validation sub-datasets too.
    `test_subsets`: keep only these test sub-datasets (MOJO reports ACCAD and BMLhandball apart).
    `num_betas`: shape coefficients used (default 16 belfusion, 10 mojo; an SMPL-X v1.0 npz has only
    10 shape components before its expressions). `skip_nonfinite`: skip, not raise on, NaN/inf files.
    Sub-datasets of the protocol missing under `root` are listed in `info["missing_subdatasets"]`.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"load_amass: protocol must be one of {sorted(PROTOCOLS)}, got {protocol!r}")
    root = Path(root).expanduser()
    if model_path is None:
        raise ValueError(f"load_amass: model_path is required. {MODEL_HELP}")
    model_path = Path(model_path).expanduser()
    if not model_path.exists():
        raise FileNotFoundError(f"{model_path}: no such body model file or folder. {MODEL_HELP}")
    mojo = protocol == "mojo"
    set_name, vertices = read_marker_vertices(marker_vertices) if mojo else ("", {})
    num_betas = NUM_BETAS[protocol] if num_betas is None else int(num_betas)
    split = MOJO_SPLIT if mojo else BELFUSION_SPLIT
    train_names = split["train"] + (BELFUSION_SPLIT["validation"] if include_validation and not mojo else ())
    test_names = split["test"]
    if test_subsets is not None:
        bad = [n for n in test_subsets if n not in split["test"]]
        if bad:
            raise ValueError(f"load_amass: test_subsets {bad} are not test sub-datasets of {protocol!r} {split['test']}")
        test_names = tuple(test_subsets)
    found, unknown = find_sequences(root)

    prot = PROTOCOLS[protocol]
    settings = {"protocol": protocol, "num_betas": num_betas, "vertices": list(vertices.items()), "skip_nonfinite": skip_nonfinite}
    cache = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir().parent / "amass"
    bodies: dict[Path, SmplxBody] = {}

    def body_for(f: Path, a: AmassFile) -> SmplxBody:
        mf = model_file(model_path, a.gender)
        want = NUM_JOINTS if mojo or a.model_type == "smplx" else SMPLH_NUM_JOINTS
        got = _model_joint_count(mf)
        if got != want:
            kind = {NUM_JOINTS: "SMPL-X", SMPLH_NUM_JOINTS: "SMPL-H"}
            why = "MOJO's markers are SMPL-X vertices" if mojo else f"the file's poses are {kind[want]} ({a.poses.shape[1]} wide)"
            raise DataError(f, f"needs an {kind[want]} model ({why}), but {mf} is {kind.get(got, 'neither')} ({got} joints). {MODEL_HELP}")
        if mf not in bodies:
            bodies[mf] = load_smplx(mf, vertices, num_betas=num_betas, num_pca_comps=12 if mojo else 0, flat_hand_mean=not mojo)
        body = bodies[mf]
        if tuple(body.parents[: len(SMPL_BODY_PARENTS)]) != SMPL_BODY_PARENTS:
            raise DataError(mf, f"joints 0-21 have parents {body.parents[:22]}, not SMPL's {SMPL_BODY_PARENTS}")
        if len(a.betas) < num_betas:
            raise DataError(f, f"betas has {len(a.betas)} values, the protocol uses num_betas={num_betas}")
        return body

    train, test, skipped, rates, caches = [], [], [], {}, []
    for names, out in ((train_names, train), (test_names, test)):
        for sub in names:
            files = found.get(sub, [])
            if not files:
                continue
            seqs, mocap_fps, sub_skipped, sub_cache = _subset(root, sub, files, prot["fps"], body_for, settings, model_path, cache)
            out += seqs
            caches.append(str(sub_cache))
            skipped += sub_skipped
            for s, r in zip(seqs, mocap_fps):
                rates[f"{r:g}->{s.fps:g}"] = rates.get(f"{r:g}->{s.fps:g}", 0) + 1
    missing = [n for n in train_names + test_names if not found.get(n)]
    for which, seqs, names in (("training", train, train_names), ("test", test, test_names)):
        if not seqs:
            raise DataError(
                root, f"no {which} sequence: none of the {protocol} {which} sub-datasets {list(names)} has a "
                f"*_poses.npz / *_stageii.npz file (found sub-datasets {sorted(n for n in found if found[n])}, "
                f"other folders {unknown})"
            )  # fmt: skip
    info = {
        "source": str(root),
        "protocol": protocol,
        "up_axis": 2,
        "subdatasets": {"train": [n for n in train_names if found.get(n)], "test": [n for n in test_names if found.get(n)]},
        "missing_subdatasets": missing,
        "ignored_folders": unknown,
        "skipped": skipped,
        "rates": rates,
        "downsample": "every round(mocap_framerate / fps)-th frame from the first (BeLFusion, MOJO)",
        "model_path": str(model_path),
        "cache": caches,
    }
    if mojo:
        names = tuple(vertices)
        info |= {"frames": "global", "ground": "future_heel_min", "point_names": names, "marker_set": set_name}
        if model_path.is_file():  # a body for recursive projection (`methods.mojo`): only when one model drives all
            info["body"] = bodies.get(model_path) or load_smplx(model_path, vertices, num_betas=num_betas)
        skeleton = marker_skeleton(names)
        name = f"amass_mojo_{set_name}"
    else:
        skeleton = Skeleton(SMPL_BODY_JOINT_NAMES, SMPL_BODY_PARENTS)
        info["left_right_pairs"] = left_right_pairs(SMPL_BODY_JOINT_NAMES)
        name = "amass_belfusion"
    return MotionDataset(name=name, skeleton=skeleton, **prot, train=train, test=test, info=info)


def _subset(root: Path, sub: str, files: list[Path], fps: float, body_for, settings: dict, model_path: Path, cache_root: Path):
    """Returns `(sequences, their mocap rates, skipped files, cache file)` of one sub-dataset, read from its
    cache file, or computed and cached."""
    mojo = settings["protocol"] == "mojo"
    stats = [(str(f.relative_to(root)), f.stat().st_size, f.stat().st_mtime_ns) for f in files]
    models = [model_path] if model_path.is_file() else sorted(list(model_path.glob("*.npz")) + list(model_path.glob("*/model.npz")))
    key = json.dumps(
        [_CACHE_VERSION, sub, fps, settings, stats, [(str(m.resolve()), m.stat().st_size, m.stat().st_mtime_ns) for m in models]],
        sort_keys=True,
    )  # fmt: skip
    path = cache_root / f"{settings['protocol']}_{sub}_{hashlib.sha256(key.encode()).hexdigest()[:20]}.npz"
    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            c = {k: z[k] for k in z.files}
    else:
        c = _compute_subset(root, files, fps, mojo, body_for, settings["skip_nonfinite"])
        savez_atomic(path, **c)
    splits = np.cumsum(c["lengths"])[:-1]
    positions = np.split(c["positions"], splits) if len(c["lengths"]) else []  # np.split(x, []) is [x]
    canon = np.split(c["canon"], splits) if mojo and positions else [None] * len(positions)
    seqs = [
        Sequence(pos, float(c["fps"][i]), str(c["subjects"][i]), str(c["actions"][i]), name=str(c["names"][i]), canon=cn)
        for i, (pos, cn) in enumerate(zip(positions, canon))
    ]
    skipped = [f"{n}: {r}" for n, r in zip(c["skipped_names"].tolist(), c["skipped_reasons"].tolist())]
    return seqs, c["mocap_fps"].tolist(), skipped, path


def _compute_subset(root: Path, files: list[Path], fps: float, mojo: bool, body_for, skip_nonfinite: bool) -> dict:
    """Returns the cache arrays of one sub-dataset's files: positions (joints or markers), canon, names, rates."""
    out = {k: [] for k in ("names", "subjects", "actions", "fps", "mocap_fps", "lengths", "positions", "canon")}
    skipped_names, skipped_reasons = [], []
    for f in files:
        rel = f.relative_to(root)
        a = read_amass_file(f, skip_nonfinite)
        if a is None:
            skipped_names.append(str(rel))
            skipped_reasons.append("NaN or inf in poses, trans or betas")
            continue
        step = frame_stride(a.fps, fps)
        if step < 1:
            skipped_names.append(str(rel))
            skipped_reasons.append(f"{a.fps:g} fps is under half of {fps:g}")
            continue
        body = body_for(f, a)
        poses, trans = a.poses[::step], a.trans[::step]
        betas = a.betas[: body.num_betas]
        joints, markers = sequence_points(body, poses, trans, betas) if mojo else (body_joints(body, poses, trans, betas), None)
        check_positions(f, joints, "joint positions", units="from the body model, in metres")
        if mojo:
            check_positions(f, markers, "marker positions", units="from the body model, in metres")
        stem = f.name
        for suffix in SEQUENCE_SUFFIXES:
            stem = stem.removesuffix(suffix)
        out["names"].append(str(rel.with_suffix("")))
        out["subjects"].append("/".join(rel.parts[:-1]))
        out["actions"].append(stem)
        out["fps"].append(a.fps / step)
        out["mocap_fps"].append(a.fps)
        out["lengths"].append(len(poses))
        if mojo:
            canon = mojo_canon(joints, trans)
            check_finite(f, canon, "canonical frames (hips on a vertical line?)")
            out["positions"].append(markers.astype(np.float32))
            out["canon"].append(canon)
        else:
            out["positions"].append(joints.astype(np.float32))
    width = len(SMPL_BODY_PARENTS)
    return {
        "names": np.array(out["names"], dtype=str), "subjects": np.array(out["subjects"], dtype=str),
        "actions": np.array(out["actions"], dtype=str), "fps": np.array(out["fps"], np.float64),
        "mocap_fps": np.array(out["mocap_fps"], np.float64), "lengths": np.array(out["lengths"], np.int64),
        "positions": np.concatenate(out["positions"]) if out["positions"] else np.zeros((0, width, 3), np.float32),
        "canon": np.concatenate(out["canon"]) if out["canon"] else np.zeros((0, 4, 3), np.float32),
        "skipped_names": np.array(skipped_names, dtype=str), "skipped_reasons": np.array(skipped_reasons, dtype=str),
    }  # fmt: skip
