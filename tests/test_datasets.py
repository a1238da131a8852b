"""Dataset loaders on fabricated files with the real layouts, and on the real shared data."""

from __future__ import annotations

import json
import re
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.data import datasets, windows
from jaxmotion.data.datasets import load_bandai, load_bvh_folder, load_dataset, load_h36m, load_humaneva

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
BANDAI_DIR = SHARED_DATA / "bandai-namco-2"
CMU_DIR = SHARED_DATA / "cmu-bvh"


def num_test_windows(ds) -> int:
    """Returns the protocol's test window count (windows start every t_his frames)."""
    frames = windows.sequence_frames(ds.test)
    return len(windows.test_windows(frames, ds.t_his, ds.t_pred, step=ds.t_his)[0])


# --- Human3.6M ------------------------------------------------------------------------------------

H36M_LENGTHS = {
    "S1": {"Walking": 130}, "S5": {"Eating": 140}, "S6": {"Directions": 126}, "S7": {"Posing": 300},
    "S8": {"Sitting 1": 125},
    # Test windows: range(0, T - 125, 25): 200 -> 3, 126 -> 1, 125 -> 0, 151 -> 2; 6 in all.
    "S9": {"Walking": 200, "Eating": 126}, "S11": {"Sitting 1": 125, "Posing 1": 151},
}  # fmt: skip


def joint_coded(t: int, num_joints: int) -> np.ndarray:
    """Returns `(t, J, 3)` positions where joint j sits at (j, 2j, -j) + a per-frame shift."""
    j = np.arange(num_joints, dtype=np.float32)
    pose = np.stack([j, 2 * j, -j], axis=-1)
    return pose[None] + np.arange(t, dtype=np.float32)[:, None, None] * 0.01


def save_positions_3d(path: Path, data) -> Path:
    np.savez(path, positions_3d=np.array(data, dtype=object))
    return path


@pytest.fixture
def h36m_npz(tmp_path) -> Path:
    data = {s: {a: joint_coded(t, 32) for a, t in acts.items()} for s, acts in H36M_LENGTHS.items()}
    data["S2"] = {"Walking": joint_coded(10, 32)}  # not a protocol subject: ignored
    return save_positions_3d(tmp_path / "data_3d_h36m.npz", data)


def test_h36m(h36m_npz):
    ds = load_h36m(h36m_npz)
    assert (ds.fps, ds.t_his, ds.t_pred, ds.mm_threshold) == (50, 25, 100, 0.5)
    assert ds.skeleton.parents == (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)
    assert ds.dim == 48
    assert sorted({s.subject for s in ds.train}) == ["S1", "S5", "S6", "S7", "S8"]
    assert sorted({s.subject for s in ds.test}) == ["S11", "S9"]
    frames = windows.sequence_frames(ds.test)
    assert all(f.shape[1] == 48 for f in frames)
    # Joint j was placed at (j, 2j, -j), so a frame lists the kept joints' original indices.
    kept = np.array([1, 2, 3, 6, 7, 8, 12, 13, 14, 15, 17, 18, 19, 25, 26, 27])
    np.testing.assert_allclose(frames[0][0].reshape(16, 3), np.stack([kept, 2 * kept, -kept], -1))
    assert num_test_windows(ds) == 6
    assert load_dataset(str(h36m_npz)).name == "h36m"


def test_h36m_parents_follow_the_32_joint_skeleton():
    # Each kept joint's parent is its nearest kept ancestor in VideoPose3D's 32-joint tree, except
    # the shoulders, which DLow / VideoPose3D rewire from the spine (32-joint 12) to the thorax (13).
    kept = datasets.H36M_KEPT_JOINTS
    for k, p in enumerate(datasets.H36M_PARENTS[1:], start=1):
        ancestor = datasets.H36M_PARENTS_32[kept[k]]
        while ancestor not in kept:
            ancestor = datasets.H36M_PARENTS_32[ancestor]
        expected = 13 if datasets.H36M_JOINT_NAMES[k] in ("LShoulder", "RShoulder") else ancestor
        assert kept[p] == expected, datasets.H36M_JOINT_NAMES[k]


# --- HumanEva-I -------------------------------------------------------------------------------------

HUMANEVA_LENGTHS = {
    "Train/S1": {"Walking 1 chunk0": 100}, "Train/S2": {"Jog 1 chunk0": 90},
    "Train/S3": {"Walking 1 chunk0": 100, "Walking 1 chunk1": 100, "Walking 1 chunk2": 100},
    # Test windows: range(0, T - 75, 15): 100 -> 2, 76 -> 1, 120 -> 3; chunk4 (300) is dropped.
    "Validate/S1": {"Walking 1 chunk0": 100}, "Validate/S2": {"Jog 1 chunk0": 76},
    "Validate/S3": {"Walking 1 chunk4": 300, "Box 1 chunk0": 120},
}  # fmt: skip


@pytest.fixture
def humaneva_npz(tmp_path) -> Path:
    data = {s: {a: joint_coded(t, 15) for a, t in acts.items()} for s, acts in HUMANEVA_LENGTHS.items()}
    return save_positions_3d(tmp_path / "data_3d_humaneva15.npz", data)


def test_humaneva(humaneva_npz):
    ds = load_humaneva(humaneva_npz)
    assert (ds.fps, ds.t_his, ds.t_pred, ds.mm_threshold) == (60, 15, 60, 0.5)
    assert ds.skeleton.parents == (-1, 0, 1, 2, 3, 1, 5, 6, 0, 8, 9, 0, 11, 12, 1)
    assert ds.dim == 42
    assert all(f.shape[1] == 42 for f in windows.sequence_frames(ds.train + ds.test))
    names = {s.name for s in ds.train + ds.test}
    assert {"Train/S3/Walking 1 chunk1", "Validate/S3/Box 1 chunk0"} <= names
    for dropped in ("Train/S3/Walking 1 chunk0", "Train/S3/Walking 1 chunk2", "Validate/S3/Walking 1 chunk4"):
        assert dropped not in names
    assert "Train/S1/Walking 1 chunk0" in names  # only S3's chunks are dropped
    assert len(ds.train) == 3 and len(ds.test) == 3
    assert num_test_windows(ds) == 6
    assert ds.info["left_right_pairs"] == [(2, 5), (3, 6), (4, 7), (8, 11), (9, 12), (10, 13)]
    assert load_dataset(humaneva_npz).name == "humaneva"


# --- corrupt npz files ------------------------------------------------------------------------------


def corrupt(kind: str, path: Path) -> Path:
    good = {s: {a: joint_coded(t, 32) for a, t in acts.items()} for s, acts in H36M_LENGTHS.items()}
    if kind == "truncated":
        save_positions_3d(path, good)
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif kind == "not_a_zip":
        path.write_bytes(b"this is not an npz file" * 10)
    elif kind == "missing_key":
        np.savez(path, positions=np.zeros(3))
    elif kind == "wrong_shape":
        good["S9"]["Walking"] = joint_coded(200, 31)
        save_positions_3d(path, good)
    elif kind == "nan":
        good["S11"]["Posing 1"][5, 3, 1] = np.nan
        save_positions_3d(path, good)
    elif kind == "missing_subject":
        del good["S11"]
        save_positions_3d(path, good)
    elif kind == "not_a_dict":
        np.savez(path, positions_3d=np.zeros((3, 32, 3)))
    return path


@pytest.mark.parametrize(
    "kind", ["truncated", "not_a_zip", "missing_key", "wrong_shape", "nan", "missing_subject", "not_a_dict"]
)
def test_corrupt_npz_error_names_the_file(tmp_path, kind):
    path = corrupt(kind, tmp_path / f"h36m_{kind}.npz")
    with pytest.raises(ValueError, match=re.escape(path.name)):
        load_h36m(path)


def test_npz_with_unknown_keys(tmp_path):
    path = save_positions_3d(tmp_path / "other.npz", {"subject_a": {"x": joint_coded(5, 32)}})
    with pytest.raises(ValueError, match="other.npz"):
        load_dataset(path)


def test_missing_paths(tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.npz"):
        load_h36m(tmp_path / "absent.npz")
    with pytest.raises(FileNotFoundError, match="absent_dir"):
        load_dataset(tmp_path / "absent_dir")


# --- Bandai-Namco-2 layout, fabricated ------------------------------------------------------------

CONTENTS = ["walk", "run"]
STYLES = ["active", "normal", "elderly"]


def bandai_like_bvh(num_frames: int, seed: int) -> str:
    """Returns a Bandai-style BVH: ground node, Hips with 6 channels, a left and a right leg."""
    joints = [("joint_Root", -1, (0, 0, 0)), ("Hips", 0, (1, 90, -400)), ("Spine", 1, (0, 15, 0)),
              ("UpperLeg_L", 1, (10, -5, 0)), ("LowerLeg_L", 3, (0, -40, 0)),
              ("UpperLeg_R", 1, (-10, -5, 0)), ("LowerLeg_R", 5, (0, -40, 0))]  # fmt: skip
    lines = ["HIERARCHY"]
    depth = 0
    for i, (name, parent, offset) in enumerate(joints):
        # Close the blocks of joints that are not ancestors of this one.
        chain, p = [], parent
        while p >= 0:
            chain.append(p)
            p = joints[p][1]
        while depth > len(chain):
            depth -= 1
            lines.append("  " * depth + "}")
        pad = "  " * depth
        lines += [pad + ("ROOT " if parent < 0 else "JOINT ") + name, pad + "{",
                  pad + "  OFFSET " + " ".join(map(str, offset)),
                  pad + "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]  # fmt: skip
        depth += 1
    while depth:
        depth -= 1
        lines.append("  " * depth + "}")
    rng = np.random.default_rng(seed)
    motion = np.zeros((num_frames, 6 * len(joints)))
    for j, (_, _, offset) in enumerate(joints[1:], start=1):
        motion[:, 6 * j : 6 * j + 3] = offset
        motion[:, 6 * j + 3 : 6 * j + 6] = rng.uniform(-30, 30, (num_frames, 3))
    motion[:, 6:9] += rng.normal(0, 1, (num_frames, 3))
    lines += ["MOTION", f"Frames:\t{num_frames}", "Frame Time:\t0.0333333"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in motion]
    return "\n".join(lines) + "\n"


# (content, style, id, frames). Test windows: range(0, T - 75, 15): 106 -> 3 (0, 15, 30), 90 -> 1.
BANDAI_CLIPS = [("walk", "active", 1, 80), ("run", "active", 2, 100), ("walk", "normal", 1, 106),
                ("run", "normal", 3, 90), ("walk", "elderly", 1, 80)]  # fmt: skip


def write_bandai_folder(folder: Path, clips=BANDAI_CLIPS, labels: bool = True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for k, (content, style, i, t) in enumerate(clips):
        stem = f"dataset-2_{content}_{style}_{i:03d}"
        (folder / f"{stem}.bvh").write_text(bandai_like_bvh(t, k))
        label = {"content": CONTENTS.index(content), "style": STYLES.index(style)}
        (folder / f"{stem}.json").write_text(json.dumps(label))
    if labels:
        (folder / "content_label.txt").write_text("\n".join("dataset-2_" + c for c in CONTENTS))
        (folder / "style_label.txt").write_text("\n".join("dataset-2_" + s for s in STYLES))
    return folder


def check_fabricated_bandai(ds):
    assert (ds.fps, ds.t_his, ds.t_pred, ds.mm_threshold) == (30, 15, 60, 0.5)
    assert ds.skeleton.names[0] == "Hips" and ds.skeleton.parents[0] == -1
    assert "joint_Root" not in ds.skeleton.names
    assert ds.dim == 5 * 3
    assert [s.name for s in ds.train] == ["dataset-2_run_active_002", "dataset-2_walk_active_001"]
    assert [s.action for s in ds.test] == ["run", "walk"]  # elderly is neither train nor test
    assert ds.info["skipped_clips"] == 1 and ds.info["up_axis"] == 1
    shin = np.linalg.norm(ds.test[0].positions[:, 3] - ds.test[0].positions[:, 2], axis=-1)
    np.testing.assert_allclose(shin, 0.40, atol=1e-5)  # 40 cm -> 0.40 m
    assert num_test_windows(ds) == 4


def test_bandai_folder(tmp_path):
    ds = load_bandai(write_bandai_folder(tmp_path / "clips"))
    check_fabricated_bandai(ds)
    assert load_dataset(tmp_path / "clips").name == "bandai2"


def test_bandai_tarball_is_extracted_once(tmp_path):
    clips = write_bandai_folder(tmp_path / "clips", labels=False)
    root = tmp_path / "root"
    root.mkdir()
    with tarfile.open(root / "bandai2_dev.tar.xz", "w:xz") as tf:
        for f in sorted(clips.iterdir()):
            tf.add(f, arcname=f.name)
    write_bandai_folder(tmp_path / "labels_only", clips=[])
    for f in ("content_label.txt", "style_label.txt"):
        shutil.copy(tmp_path / "labels_only" / f, root / f)
    cache = tmp_path / "cache" / "bandai2"
    check_fabricated_bandai(load_bandai(root, cache_dir=cache))
    marker = cache / ".extracted"
    assert marker.is_file()
    stamp = marker.stat().st_mtime_ns
    check_fabricated_bandai(load_dataset(root, cache_dir=cache))
    assert marker.stat().st_mtime_ns == stamp  # reused, not extracted again


def test_bandai_label_mismatch(tmp_path):
    folder = write_bandai_folder(tmp_path / "clips")
    (folder / "dataset-2_walk_active_001.json").write_text(json.dumps({"content": 1, "style": 0}))
    with pytest.raises(ValueError, match="dataset-2_walk_active_001.json"):
        load_bandai(folder)


def test_bandai_truncated_clip(tmp_path):
    folder = write_bandai_folder(tmp_path / "clips")
    path = folder / "dataset-2_run_normal_003.bvh"
    path.write_text(path.read_text()[:-2000])
    with pytest.raises(ValueError, match=path.name):
        load_bandai(folder)


def test_bvh_folder_generic(tmp_path):
    folder = write_bandai_folder(tmp_path / "clips", labels=False)
    for f in folder.glob("*.bvh"):
        f.rename(folder / f.name.replace("dataset-2_", "take_"))
    split = lambda f: "train" if "active" in f.name else ("test" if "normal" in f.name else None)  # noqa: E731
    ds = load_bvh_folder(folder, split=split)
    assert ds.skeleton.names[0] == "Hips"  # the ground node is dropped
    assert (len(ds.train), len(ds.test)) == (2, 2)
    assert (ds.fps, ds.t_his, ds.t_pred) == (30.0, 15, 60)  # 0.5 s -> 2 s
    shin = np.linalg.norm(ds.test[0].positions[:, 3] - ds.test[0].positions[:, 2], axis=-1)
    np.testing.assert_allclose(shin, 0.40, atol=1e-5)  # units guessed: centimetres
    everything = load_dataset(folder)
    assert (len(everything.train), len(everything.test)) == (0, 5)


# --- real data --------------------------------------------------------------------------------------


def test_cmu_folder():
    if not (CMU_DIR / "01_01.bvh").is_file():
        pytest.skip(f"shared data not found at {CMU_DIR}")
    ds = load_dataset(CMU_DIR, downsample=4)
    assert ds.skeleton.num_joints == 31 and ds.dim == 90
    assert (ds.fps, ds.t_his, ds.t_pred) == (30.0, 15, 60)
    assert [s.name for s in ds.test] == ["01_01.bvh", "01_03.bvh"]
    assert ds.test[0].positions.shape == (688, 31, 3)  # 2752 frames at 120 fps, every 4th
    assert ds.test[0].subject == "01"
    feet = ds.test[0].positions[:, [5, 10], 1]  # toes, metres above the floor (Y-up)
    assert -0.1 < feet.min() < 0.1


@pytest.fixture(scope="module")
def bandai_sample(tmp_path_factory) -> Path:
    """Returns a folder with 2 active and 1 normal real clip from the tarball's head (about 1 s)."""
    tarball = BANDAI_DIR / "bandai2_dev.tar.xz"
    if not tarball.is_file():
        pytest.skip(f"shared data not found at {tarball}")
    out = tmp_path_factory.mktemp("bandai_sample")
    want, pending = {"active": 2, "normal": 1}, 0  # clips to take, JSON files still to come
    with tarfile.open(tarball) as tf:
        for member in tf:  # streams: getmember() would decompress the whole archive
            stem, ext = member.name.rsplit(".", 1)
            style = stem.split("_")[-2]
            if ext == "bvh" and want.get(style, 0) > 0:
                want[style] -= 1
                pending += 1
            elif not (ext == "json" and (out / f"{stem}.bvh").is_file()):
                continue
            elif ext == "json":
                pending -= 1
            tf.extract(member, out, filter="data")
            if not any(want.values()) and pending == 0:
                break
    for f in ("content_label.txt", "style_label.txt"):
        shutil.copy(BANDAI_DIR / f, out / f)
    return out


def test_bandai_real_clips(bandai_sample):
    ds = load_dataset(bandai_sample)
    assert ds.name == "bandai2" and ds.skeleton.num_joints == 21 and ds.dim == 60
    assert ds.skeleton.names[0] == "Hips"
    assert (len(ds.train), len(ds.test)) == (2, 1)
    assert ds.test[0].action == "raise-up-both-hands"
    assert len(ds.info["left_right_pairs"]) == 8
    pos = ds.train[0].positions
    parents = ds.skeleton.parents
    lengths = np.stack([np.linalg.norm(pos[:, j] - pos[:, p], axis=-1) for j, p in enumerate(parents) if p >= 0], 1)
    assert np.all((lengths > 0.04) & (lengths < 0.5))  # metres, not centimetres
    np.testing.assert_allclose(lengths, np.broadcast_to(lengths[0], lengths.shape), atol=1e-4)


def test_bandai_corrupt_tarball_and_foreign_cache(tmp_path):
    root = tmp_path / "root"
    root.mkdir()
    clips = write_bandai_folder(tmp_path / "clips")
    with tarfile.open(root / "bandai2_dev.tar.xz", "w:xz") as tf:
        tf.add(clips / "dataset-2_walk_normal_001.bvh", arcname="dataset-2_walk_normal_001.bvh")
    tarball = root / "bandai2_dev.tar.xz"
    tarball.write_bytes(tarball.read_bytes()[:300])
    with pytest.raises(ValueError, match="bandai2_dev.tar.xz"):
        load_bandai(root, cache_dir=tmp_path / "cache")
    assert not (tmp_path / "cache").exists()
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    with pytest.raises(ValueError, match="mine"):
        load_bandai(root, cache_dir=foreign)
    assert (foreign / "notes.txt").is_file()
