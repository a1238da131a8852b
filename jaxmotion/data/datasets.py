"""Dataset definitions under the evaluation protocol ([protocol §4][datasets]), each a `MotionDataset`.

| loader | data | fps | t_his -> t_pred | joints kept (root first) | train / test |
| --- | --- | --- | --- | --- | --- |
| `load_h36m` | `data_3d_h36m.npz` (VideoPose3D) | 50 | 25 -> 100 | 17 | S1 S5 S6 S7 S8 / S9 S11 |
| `load_humaneva` | `data_3d_humaneva15.npz` (VideoPose3D) | 60 | 15 -> 60 | 15 | Train/S1-3 / Validate/S1-3 |
| `load_bandai` | Bandai-Namco-2 BVH (tarball or folder) | 30 | 15 -> 60 | 21 (no `joint_Root`) | 4 styles / style normal |
| `load_bvh_folder` | any folder of BVH files | file's, or `fps` | 0.5 s -> 2 s | all but a ground node | user's `split` (default all test) |

Positions are global, in metres, `(T, J, 3)`; `windows.to_frames` makes them root-relative and
drops the root. `load_dataset(spec)` picks the loader from a path. `info` records `up_axis` (for
`augment.rotate_yaw`), `left_right_pairs` (for `augment.mirror`) and where the data came from.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from jaxmotion.data.augment import left_right_pairs
from jaxmotion.data.bandai import (  # noqa: F401 (BANDAI_TARBALL and default_cache_dir are public here too)
    BANDAI_NAME, BANDAI_PROTOCOL, BANDAI_TARBALL, BANDAI_TEST_STYLES, BANDAI_TRAIN_STYLES, bandai_clip_dir, default_cache_dir,
)  # fmt: skip
from jaxmotion.data.plausible import check_positions
from jaxmotion.data.types import MotionDataset, Sequence, Skeleton, check_finite
from jaxmotion.errors import DataError
from jaxmotion.formats.bvh import Bvh, forward_kinematics, guess_scale, is_ground_skeleton, read_bvh
from jaxmotion.formats.npz import read_array_dict

# ----------------------------------------------------------------------------------------------
# Human3.6M (VideoPose3D's data_3d_h36m.npz, metres, Z up)

H36M_PARENTS_32 = (
    -1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14,
    12, 16, 17, 18, 19, 20, 19, 22, 12, 24, 25, 26, 27, 28, 27, 30,
)  # fmt: skip
H36M_KEPT_JOINTS = (0, 1, 2, 3, 6, 7, 8, 12, 13, 14, 15, 17, 18, 19, 25, 26, 27)
H36M_JOINT_NAMES = (
    "Hip", "RHip", "RKnee", "RFoot", "LHip", "LKnee", "LFoot", "Spine", "Thorax", "Neck", "Head",
    "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist",
)  # fmt: skip

def _h36m_parents() -> tuple[int, ...]:
    """Returns the 17 kept joints' parents: nearest kept ancestor, shoulders rewired to the thorax.

    Removing joints 16 and 24 (the shoulder blades, children of 12) would hang the shoulders on
    kept joint 7 (32-joint 12, "Spine"); DLow and VideoPose3D then set `_parents[11] = 8` and
    `_parents[14] = 8` (the thorax), the 17-joint tree everyone uses.
    """
    parents = list(_remap_parents(H36M_PARENTS_32, H36M_KEPT_JOINTS))
    parents[11] = parents[14] = 8
    return tuple(parents)


H36M_TRAIN_SUBJECTS = ("S1", "S5", "S6", "S7", "S8")
H36M_TEST_SUBJECTS = ("S9", "S11")

# ----------------------------------------------------------------------------------------------
# HumanEva-I (VideoPose3D's data_3d_humaneva15.npz, metres, Z up). Parents are DLow's /
# VideoPose3D's `humaneva_skeleton`; the names are VideoPose3D's HUMANEVA_KEYPOINTS, and the two
# agree: every limb hangs off thorax (arms, head) or pelvis (legs), left before right.

HUMANEVA_PARENTS = (-1, 0, 1, 2, 3, 1, 5, 6, 0, 8, 9, 0, 11, 12, 1)
HUMANEVA_JOINT_NAMES = (
    "pelvis", "thorax", "lsho", "lelb", "lwri", "rsho", "relb", "rwri",
    "lhip", "lkne", "lank", "rhip", "rkne", "rank", "head",
)  # fmt: skip
HUMANEVA_TRAIN_SUBJECTS = ("Train/S1", "Train/S2", "Train/S3")
HUMANEVA_TEST_SUBJECTS = ("Validate/S1", "Validate/S2", "Validate/S3")
# DLow: "these takes have wrong head position, excluded from training and testing".
HUMANEVA_DROPPED = (
    ("Train/S3", "Walking 1 chunk0"),
    ("Train/S3", "Walking 1 chunk2"),
    ("Validate/S3", "Walking 1 chunk4"),
)

# ----------------------------------------------------------------------------------------------
# ----------------------------------------------------------------------------------------------
# npz datasets


def load_h36m(npz_path: str | os.PathLike) -> MotionDataset:
    """Returns Human3.6M under the protocol: 17 joints, 50 fps, 25 -> 100 frames, S9 S11 test.

    `npz_path` is VideoPose3D's `data_3d_h36m.npz`: key `positions_3d` holding a pickled
    `{subject: {action: (T, 32, 3) array}}` in metres. Subjects other than the seven of the
    protocol are ignored; every protocol subject must be present.
    """
    path = Path(npz_path)
    return _h36m_from_dict(_read_positions_3d(path), path)


def load_humaneva(npz_path: str | os.PathLike) -> MotionDataset:
    """Returns HumanEva-I under the protocol: 15 joints, 60 fps, 15 -> 60 frames, Validate/* test.

    `npz_path` is VideoPose3D's `data_3d_humaneva15.npz`: key `positions_3d` holding a pickled
    `{'Train/S1': {action: (T, 15, 3) array}, 'Validate/S1': ...}` in metres. DLow's three takes
    with a wrong head position (`HUMANEVA_DROPPED`) are dropped when present.
    """
    path = Path(npz_path)
    return _humaneva_from_dict(_read_positions_3d(path), path)


def _read_positions_3d(path: Path) -> dict:
    """Returns the `positions_3d` dict of a VideoPose3D npz (`formats.npz.read_array_dict`: no code runs from the file)."""
    return read_array_dict(path, "positions_3d")


def _npz_sequences(
    data: dict, path: Path, subjects: tuple[str, ...], num_joints: int, fps: float,
    keep: tuple[int, ...], dropped: tuple[tuple[str, str], ...] = (),
) -> list[Sequence]:  # fmt: skip
    missing = [s for s in subjects if s not in data]
    if missing:
        raise DataError(path, f"subjects {missing} missing from 'positions_3d' (has {sorted(data, key=str)})")
    out = []
    for subject in subjects:
        for action in sorted(data[subject], key=str):
            if (subject, action) in dropped:
                continue
            arr = data[subject][action]
            where = f"positions_3d[{subject!r}][{action!r}]"
            if not isinstance(arr, np.ndarray) or arr.ndim != 3 or arr.shape[1:] != (num_joints, 3):
                shape = arr.shape if isinstance(arr, np.ndarray) else type(arr).__name__
                raise DataError(path, f"{where} must be a (T, {num_joints}, 3) array, got {shape}")
            pos = check_positions(path, arr, where, units="metres, as VideoPose3D stores them")[:, list(keep)]
            out.append(Sequence(pos, fps, subject, str(action), name=f"{subject}/{action}"))
    return out


def _h36m_from_dict(data: dict, path: Path) -> MotionDataset:
    seq = lambda subjects: _npz_sequences(data, path, subjects, 32, 50.0, H36M_KEPT_JOINTS)  # noqa: E731
    names, parents = H36M_JOINT_NAMES, H36M_PARENTS
    return MotionDataset(
        name="h36m",
        skeleton=Skeleton(names, parents),
        fps=50.0,
        t_his=25,
        t_pred=100,
        mm_threshold=0.5,
        train=seq(H36M_TRAIN_SUBJECTS),
        test=seq(H36M_TEST_SUBJECTS),
        info={"source": str(path), "up_axis": 2, "left_right_pairs": left_right_pairs(names)},
    )


def _humaneva_from_dict(data: dict, path: Path) -> MotionDataset:
    keep = tuple(range(15))
    seq = lambda s: _npz_sequences(data, path, s, 15, 60.0, keep, HUMANEVA_DROPPED)  # noqa: E731
    return MotionDataset(
        name="humaneva",
        skeleton=Skeleton(HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS),
        fps=60.0,
        t_his=15,
        t_pred=60,
        mm_threshold=0.5,
        train=seq(HUMANEVA_TRAIN_SUBJECTS),
        test=seq(HUMANEVA_TEST_SUBJECTS),
        info={
            "source": str(path),
            "up_axis": 2,
            "left_right_pairs": left_right_pairs(HUMANEVA_JOINT_NAMES),
            "dropped": [f"{s}/{a}" for s, a in HUMANEVA_DROPPED if a in data.get(s, {})],
        },
    )


def _remap_parents(parents: tuple[int, ...], keep: tuple[int, ...]) -> tuple[int, ...]:
    """Returns the parents of the kept joints, each the nearest kept ancestor, as kept indices."""
    new_index = {old: new for new, old in enumerate(keep)}
    out = []
    for j in keep:
        p = parents[j]
        while p >= 0 and p not in new_index:
            p = parents[p]
        out.append(new_index[p] if p >= 0 else -1)
    if out.count(-1) != 1 or out[0] != -1:
        raise ValueError(f"kept joints {keep} must contain the root first and one root only")
    return tuple(out)


H36M_PARENTS = _h36m_parents()  # (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)


# ----------------------------------------------------------------------------------------------
# BVH datasets


def load_bandai(root: str | os.PathLike, cache_dir: str | os.PathLike | None = None) -> MotionDataset:
    """Returns Bandai-Namco-2 under the protocol: 21 joints (Hips root), 30 fps, 15 -> 60 frames.

    `root` is the folder holding `bandai2_dev.tar.xz` (extracted once into `cache_dir`, default
    `default_cache_dir()`, and reused from there) or a folder of already extracted clips. Train
    are the styles active, exhausted, feminine, masculine; test is style normal; other styles are
    skipped. A sequence's action is its content label without the `dataset-2_` prefix (`walk`,
    `wave-left-hand`, ...). Labels come from the file name and are checked against the JSON beside
    each clip when `content_label.txt` / `style_label.txt` are found. The files name no actor, so
    `subject` is `"unknown"`. `joint_Root` (a ground node) is dropped; cm -> m.
    """
    root = Path(root).expanduser()
    clip_dir = bandai_clip_dir(root, cache_dir)
    files = sorted(p for p in clip_dir.iterdir() if p.suffix == ".bvh" and BANDAI_NAME.match(p.stem))
    if not files:
        raise DataError(clip_dir, "no Bandai-Namco-2 clips (dataset-2_{content}_{style}_{id}.bvh)")
    contents, styles = _bandai_labels(root, clip_dir)

    train, test, skipped = [], [], 0
    skeleton = None
    for f in files:
        m = BANDAI_NAME.match(f.stem)
        content, style = m["content"], m["style"]
        if contents is not None:
            _check_bandai_json(f, content, style, contents, styles)
        if style not in BANDAI_TRAIN_STYLES + BANDAI_TEST_STYLES:
            skipped += 1
            continue
        bvh = read_bvh(f)
        if abs(bvh.fps - BANDAI_PROTOCOL["fps"]) > 0.1:
            raise DataError(f, f"expected {BANDAI_PROTOCOL['fps']:g} fps, file says {bvh.fps:.3f}")
        if bvh.names[0] != "joint_Root" or len(bvh.names) < 2 or bvh.names[1] != "Hips":
            raise DataError(f, f"expected joint_Root then Hips, got {bvh.names[:2]}")
        names, parents, positions = _bvh_positions(bvh, scale=0.01, drop=1)
        if skeleton is None:
            skeleton = Skeleton(names, parents)
        elif (names, parents) != (skeleton.names, skeleton.parents):
            raise DataError(f, f"skeleton differs from {files[0].name}'s")
        seq = Sequence(positions, BANDAI_PROTOCOL["fps"], "unknown", content, name=f.stem)
        (test if style in BANDAI_TEST_STYLES else train).append(seq)
    if skeleton is None:
        styles = BANDAI_TRAIN_STYLES + BANDAI_TEST_STYLES
        raise DataError(clip_dir, f"no clip has a protocol style {styles}")
    return MotionDataset(
        name="bandai2",
        skeleton=skeleton,
        **BANDAI_PROTOCOL,
        train=train,
        test=test,
        info={
            "source": str(clip_dir),
            "up_axis": 1,
            "left_right_pairs": left_right_pairs(skeleton.names),
            "skipped_clips": skipped,
        },
    )


def _bandai_labels(root: Path, clip_dir: Path) -> tuple[list[str] | None, list[str] | None]:
    """Returns the content and style label names (without `dataset-2_`), or Nones if absent."""
    for d in (root, clip_dir):
        c, s = d / "content_label.txt", d / "style_label.txt"
        if c.is_file() and s.is_file():
            return _label_names(c), _label_names(s)
    return None, None


def _label_names(path: Path) -> list[str]:
    return [x.removeprefix("dataset-2_") for x in path.read_text().split()]


def _check_bandai_json(f: Path, content: str, style: str, contents: list[str], styles: list[str]) -> None:
    j = f.with_suffix(".json")
    if not j.is_file():
        return
    try:
        label = json.loads(j.read_text())
        c, s = contents[int(label["content"])], styles[int(label["style"])]
    except (ValueError, KeyError, IndexError, TypeError) as e:
        raise DataError(j, f"bad label file ({type(e).__name__}: {e})") from None
    if (c, s) != (content, style):
        raise DataError(j, f"labels say content {c!r} style {s!r}, file name says {content!r} {style!r}")


def skeleton_difference(names, parents, ref_names, ref_parents) -> str:
    """Returns the first difference between two skeletons (joint names and parents), named joint by joint, for an error."""
    parent = lambda ns, ps, i: ns[ps[i]] if ps[i] >= 0 else "nothing (the root)"  # noqa: E731
    missing, extra = [n for n in ref_names if n not in names], [n for n in names if n not in ref_names]
    if missing or extra:
        parts = ([f"joints {missing} missing"] if missing else []) + ([f"joints {extra} not in it"] if extra else [])
        return f"{', '.join(parts)} ({len(names)} vs {len(ref_names)} joints)"
    for i, n in enumerate(names):
        j = ref_names.index(n)
        if parent(names, parents, i) != parent(ref_names, ref_parents, j):
            return f"joint {n!r} hangs from {parent(names, parents, i)!r} here, from {parent(ref_names, ref_parents, j)!r} there"
    first = next(i for i, (a, b) in enumerate(zip(names, ref_names)) if a != b)
    return f"the same joints in another order (joint {first} is {names[first]!r} here, {ref_names[first]!r} there)"


def load_bvh_folder(
    path: str | os.PathLike,
    *,
    scale: float | dict[str, float] | None = None,
    split: Callable[[Path], str | None] | None = None,
    fps: float | None = None,
    downsample: int = 1,
    t_his: int | None = None,
    t_pred: int | None = None,
    mm_threshold: float = 0.5,
    name: str | None = None,
    root: str | None = None,
) -> MotionDataset:
    """Returns a dataset of every `*.bvh` under `path` (recursively, sorted by path).

    The dataset's root joint is decided once for the folder, from the skeleton: `root` names it (the
    joints above it must be a chain of single children, and are dropped), else a ground node is dropped
    when the skeleton has one (`formats.bvh.is_ground_skeleton`: a zero-offset root with exactly one
    child that carries the body, e.g. Bandai's `joint_Root`), whether or not it moves in a clip.
    Each file is converted to metres by its own unit (`data.units.file_scales`): `scale` (one number,
    or `{glob pattern: number}` per file), else guessed (`formats.bvh.guess_scale`; CMU's cgspeed
    skeleton is recognised, 0.056444 m/unit), and checked against a person's size; a folder that fails
    the check is one `DataError` listing every file.
    `split(file)` returns "train", "test" or None (skip the file); by default every file is test.
    `fps` resamples each file from its own frame rate to `fps` (linear interpolation of joint
    positions); without it every file must have the same rate, of which every `downsample`-th frame
    is kept. `t_his` / `t_pred` default to 0.5 s / 2 s at the resulting frame rate, as for Human3.6M
    and Bandai. A sequence's subject is the file stem before its first `_` (CMU's `SS_TT` naming) and
    its action the whole stem. All files must share one skeleton (joint names and parents); positions
    with NaN/inf are a `DataError` naming the file and frame.
    """
    from jaxmotion.data.units import file_scales
    from jaxmotion.data.windows import resample

    root_dir = Path(path).expanduser()
    if not root_dir.is_dir():
        raise FileNotFoundError(f"{root_dir}: no such folder")
    files = sorted(root_dir.rglob("*.bvh"))
    if not files:
        raise DataError(root_dir, "no .bvh files")
    if downsample < 1:
        raise ValueError(f"load_bvh_folder: downsample must be >= 1, got {downsample}")
    if fps is not None and (downsample != 1 or not fps > 0):
        raise ValueError(f"load_bvh_folder: fps must be > 0 and replaces downsample, got fps={fps}, downsample={downsample}")
    chosen, bvhs = {}, {}
    skeleton, rate, first, drop = None, None, None, 0
    for f in files:
        which = "test" if split is None else split(f)
        if which not in ("train", "test", None):
            raise ValueError(f"load_bvh_folder: split({f}) returned {which!r}, not 'train', 'test' or None")
        if which is None:
            continue
        bvh = read_bvh(f)
        if skeleton is None:
            drop = _joints_above(bvh, root) if root is not None else int(is_ground_skeleton(bvh))
            skeleton, rate, first = Skeleton(bvh.names, bvh.parents), bvh.fps / downsample, f
        elif (bvh.names, bvh.parents) != (skeleton.names, skeleton.parents):
            raise DataError(f, f"skeleton differs from {first}'s: {skeleton_difference(bvh.names, bvh.parents, skeleton.names, skeleton.parents)}")
        elif fps is None and abs(bvh.fps / downsample - rate) > 0.01 * rate:
            raise DataError(f, f"{bvh.fps / downsample:.3f} fps but {first} has {rate:.3f}; resample every file to one rate "
                               "with data_options {'fps': 30}")
        chosen[f], bvhs[f] = which, bvh
    if skeleton is None:
        raise ValueError(f"{root_dir}: split() skipped every file")
    scales = file_scales(bvhs, scale, root_dir)
    out_fps = fps if fps is not None else rate
    train, test = [], []
    for f, bvh in bvhs.items():
        names, parents, positions = _bvh_positions(bvh, scales[f], drop)
        positions = resample(positions, bvh.fps, fps).astype(np.float32) if fps is not None else positions[::downsample]
        stem = f.stem
        seq = Sequence(positions, out_fps, stem.split("_")[0], stem, name=str(f.relative_to(root_dir)))
        (train if chosen[f] == "train" else test).append(seq)
    skeleton = Skeleton(names, parents)
    out_fps = round(out_fps, 3)
    rates = sorted({round(b.fps, 3) for b in bvhs.values()})
    units = sorted({scales[f] for f in bvhs})
    return MotionDataset(
        name=name or root_dir.name,
        skeleton=skeleton,
        fps=out_fps,
        t_his=t_his if t_his is not None else max(1, round(0.5 * out_fps)),
        t_pred=t_pred if t_pred is not None else max(1, round(2.0 * out_fps)),
        mm_threshold=mm_threshold,
        train=train,
        test=test,
        info={"source": str(root_dir), "up_axis": 1, "left_right_pairs": left_right_pairs(skeleton.names),
              "file_fps": rates, "file_scales": units},
    )


def _joints_above(bvh: Bvh, root: str) -> int:
    """Returns how many joints precede joint `root`: its ancestors, which must each have exactly one child."""
    if root not in bvh.names:
        raise ValueError(f"load_bvh_folder: root={root!r} is not a joint of {bvh.path} (joints: {list(bvh.names[:8])}...)")
    r = bvh.names.index(root)
    for a in range(r):
        children = [j for j, p in enumerate(bvh.parents) if p == a]
        if children != [a + 1]:
            raise ValueError(
                f"load_bvh_folder: root={root!r}: joint {bvh.names[a]!r} above it in {bvh.path} has children "
                f"{[bvh.names[j] for j in children]}; only a chain of single children can be dropped"
            )
    return r


def _bvh_positions(
    bvh: Bvh, scale: float, drop: int | bool
) -> tuple[tuple[str, ...], tuple[int, ...], np.ndarray]:
    """Returns `(names, parents, positions (F, J, 3) float32 metres)` without the first `drop` joints (a chain).

    Positions are checked finite: huge channel values overflow in forward kinematics or in float32.
    """
    with np.errstate(over="ignore", invalid="ignore"):  # reported just below, with the file and frame
        positions = (forward_kinematics(bvh) * scale).astype(np.float32)
    check_finite(bvh.path, positions, "positions after forward kinematics")
    drop = int(drop)
    # The first kept joint becomes the root, so it is index 0 and its parent -1.
    parents = tuple(-1 if p < drop else p - drop for p in bvh.parents[drop:])
    return bvh.names[drop:], parents, positions[:, drop:]


# ----------------------------------------------------------------------------------------------


def load_dataset(spec: str | os.PathLike, **options) -> MotionDataset:
    """Returns the dataset that `spec` points to; `options` go to the chosen loader.

    - `*.npz`: Human3.6M if `positions_3d` has subject keys `S1`, `S9`, ..., HumanEva-I if it has
      `Train/S1`, `Validate/S1`, ...
    - a folder with `bandai2_dev.tar.xz` or `dataset-2_*.bvh` clips: `load_bandai`; with the option
      `markers="bandai"` (a marker set name), `jaxmotion.data.markers.load_bandai_markers`.
    - another folder with `.bvh` files: `load_bvh_folder`.
    - `amass:<root>`, or a folder of AMASS sub-dataset folders (`ACCAD/`, `CMU/`, ... holding
      `*_poses.npz`): `jaxmotion.data.amass.load_amass` (options `protocol`, `model_path`, ...).
    """
    if str(spec).startswith("amass:"):
        from jaxmotion.data.amass import load_amass  # jax and the body models: only AMASS needs them

        return load_amass(str(spec).removeprefix("amass:"), **options)
    path = Path(spec).expanduser()
    if path.suffix == ".npz":
        if options:
            raise ValueError(f"load_dataset: {path} is an npz dataset; it takes no options {sorted(options)}")
        data = _read_positions_3d(path)
        keys = list(data)
        if keys and all(re.fullmatch(r"S\d+", str(k)) for k in keys):
            return _h36m_from_dict(data, path)
        if keys and all(re.fullmatch(r"(Train|Validate)/S\d+", str(k)) for k in keys):
            return _humaneva_from_dict(data, path)
        raise DataError(
            path, f"'positions_3d' keys {sorted(map(str, keys))[:5]} are neither Human3.6M subjects "
            "('S1', ...) nor HumanEva-I ('Train/S1', 'Validate/S1', ...)"
        )
    if path.is_dir():
        if (path / BANDAI_TARBALL).is_file() or any(path.glob("dataset-2_*.bvh")):
            if "markers" in options:
                # Imported here: `markers` pulls in `jaxmotion.body` and jax, which the joint loaders do not need.
                from jaxmotion.data.markers import load_bandai_markers

                options = dict(options)
                return load_bandai_markers(path, options.pop("markers"), **options)
            return load_bandai(path, **options)
        if any(path.rglob("*.bvh")):
            return load_bvh_folder(path, **options)
        from jaxmotion.data import amass

        if amass.is_amass_root(path):
            return amass.load_amass(path, **options)
        raise DataError(path, f"folder has neither {BANDAI_TARBALL}, .bvh files nor AMASS sub-dataset folders")
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    raise DataError(path, "expected a .npz file or a folder of BVH files")
