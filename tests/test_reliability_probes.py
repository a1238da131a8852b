"""What a demanding user's probes found, each pinned: no code runs from a data file, no result is lost,
every user error is one named message (the subprocess tests check stderr for tracebacks)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.data.datasets import load_dataset, load_h36m
from jaxmotion.errors import DataError

from test_reliability import TX, _sample

# --- a data file runs no code --------------------------------------------------------------------------


class _Payload:
    """Unpickles to a call of `Path.touch(marker)`: proof that code ran, if the marker appears."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return Path.touch, (self.marker,)


@pytest.mark.parametrize("where", ["action", "subject"])
def test_a_malicious_npz_runs_no_code(tmp_path, where):
    marker = tmp_path / "ran"
    good = np.zeros((4, 32, 3), np.float32)
    data = {s: {"Walking": good} for s in ("S1", "S5", "S6", "S7", "S8", "S9", "S11")}
    if where == "action":
        data["S9"]["Eating"] = _Payload(marker)  # beside real arrays, after numpy's own globals
    else:
        data = {"S1": _Payload(marker)}
    path = tmp_path / "data_3d_h36m.npz"
    np.savez(path, positions_3d=np.array(data, dtype=object))
    for load in (load_dataset, load_h36m):
        with pytest.raises(DataError, match=r"data_3d_h36m\.npz: 'positions_3d' names pathlib\.Path\.touch, .*refused without running it"):
            load(path)
    assert not marker.exists()


def test_the_restricted_unpickler_still_reads_numpy_pickles(tmp_path):
    body = np.linspace(0.5, 1.2, 32 * 3).reshape(1, 32, 3)  # a person's size: 1.2 m from the first joint to the last
    data = {s: {"Walking": np.repeat(body, 4, 0), 7: np.repeat(body, 3, 0).astype(np.float16)}
            for s in ("S1", "S5", "S6", "S7", "S8", "S9", "S11")}
    path = tmp_path / "h.npz"
    np.savez_compressed(path, positions_3d=np.array(data, dtype=object))
    ds = load_dataset(path)
    assert ds.name == "h36m" and len(ds.train) == 10 and float(ds.train[1].positions[0, 0, 0]) == 0.5


def _humaneva_payload(path: Path, marker: Path) -> None:
    good = np.repeat(np.linspace(0.5, 1.2, 15 * 3).reshape(1, 15, 3), 4, 0)
    data = {s: {"Walking": good} for s in ("Train/S1", "Train/S2", "Train/S3", "Validate/S1", "Validate/S2", "Validate/S3")}
    data["Validate/S2"]["Box"] = _Payload(marker)
    np.savez(path, positions_3d=np.array(data, dtype=object))


def test_a_malicious_humaneva_npz_runs_no_code(tmp_path):
    from jaxmotion.data.datasets import load_humaneva

    marker, path = tmp_path / "ran", tmp_path / "data_3d_humaneva15.npz"
    _humaneva_payload(path, marker)
    for load in (load_dataset, load_humaneva):
        with pytest.raises(DataError, match=r"humaneva15\.npz: 'positions_3d' names pathlib\.Path\.touch, .*refused without running it"):
            load(path)
    assert not marker.exists()


def _object_array_payload(marker: Path) -> np.ndarray:
    return np.array([_Payload(marker)], dtype=object)


@pytest.mark.parametrize("form", ["object key", "bare pickle"])
def test_a_malicious_amass_sequence_runs_no_code(tmp_path, form):
    from jaxmotion.data.amass import read_amass_file

    marker, path = tmp_path / "ran", tmp_path / "seq_poses.npz"
    if form == "object key":
        np.savez(path, poses=np.zeros((4, 156)), trans=np.zeros((4, 3)), betas=_object_array_payload(marker),
                 mocap_framerate=np.array(120.0))
        match = r"seq_poses\.npz: key 'betas' holds pickled Python objects, refused without running them"
    else:
        import pickle

        path.write_bytes(pickle.dumps(_Payload(marker)))  # np.load(allow_pickle=True) would unpickle a non-zip file
        match = r"seq_poses\.npz: not an npz file"
    with pytest.raises(DataError, match=match):
        read_amass_file(path)
    assert not marker.exists()


def _body_model_with_payload(path: Path, marker: Path) -> Path:
    """An SMPL-H model npz with the official keys, its J_regressor a pickle whose loading touches `marker`."""
    from test_amass import SMPLH_PARENTS, fake_model

    fake_model(path, SMPLH_PARENTS, seed=0, pca=False)
    arrays = dict(np.load(path))
    arrays["J_regressor"] = _object_array_payload(marker)
    np.savez(path, **arrays)
    return path


def test_a_malicious_body_model_runs_no_code(tmp_path):
    """Through `load_smplx` and through an AMASS folder whose `model_path` names it (`jaxmotion run`'s data_options)."""
    from jaxmotion.body.smplx import load_smplx
    from jaxmotion.data.amass import load_amass

    from test_amass import write_sequence

    marker = tmp_path / "ran"
    model = _body_model_with_payload(tmp_path / "smplh" / "model.npz", marker)
    write_sequence(tmp_path / "AMASS" / "CMU" / "01" / "01_01_poses.npz", 120, 300, "male", seed=0)
    write_sequence(tmp_path / "AMASS" / "DFaust" / "50002" / "50002_hips_poses.npz", 120, 300, "male", seed=1)
    match = r"model\.npz: key 'J_regressor' holds pickled Python objects, refused without running them"
    with pytest.raises(DataError, match=match):
        load_smplx(model, {})
    with pytest.raises(DataError, match=match):
        load_amass(tmp_path / "AMASS", "belfusion", model, cache_dir=tmp_path / "cache")
    assert not marker.exists()


@pytest.mark.parametrize("form", ["object key", "bare pickle"])
def test_a_malicious_predict_input_runs_no_code(tmp_path, form):
    from jaxmotion.tools.predict_file import read_motion

    marker, path = tmp_path / "ran", tmp_path / "clip.npz"
    if form == "object key":
        np.savez(path, positions=np.zeros((4, 3, 3)), names=_object_array_payload(marker))
        match = r"clip\.npz: key 'names' holds pickled Python objects, refused without running them"
    else:
        import pickle

        path.write_bytes(pickle.dumps(_Payload(marker)))
        match = r"clip\.npz: not an npz file"
    with pytest.raises(DataError, match=match):
        read_motion(path)
    assert not marker.exists()


def test_no_reader_asks_numpy_to_unpickle():
    package = Path(__file__).resolve().parents[1] / "jaxmotion"
    found = [f"{p.relative_to(package)}:{i}" for p in package.rglob("*.py")
             for i, line in enumerate(p.read_text().splitlines(), 1)
             if "allow_pickle=True" in line or "torch.load" in line or "pickle.load(" in line]
    assert not found, found


# --- a failed write loses no result ------------------------------------------------------------------


def _failing_writes_to(monkeypatch, part: str):
    """Makes every file opened for writing whose name contains `part` fail with ENOSPC after its first 16 bytes."""
    import builtins
    import errno
    import io

    real_open = io.open

    class Full(io.FileIO):
        def write(self, b):
            if self.tell() + len(b) > 16:
                super().write(bytes(b)[: max(0, 16 - self.tell())])
                raise OSError(errno.ENOSPC, "No space left on device (injected)")
            return super().write(b)

    def open_(file, mode="r", *args, **kwargs):
        if part in os.path.basename(os.fspath(file)) and any(c in mode for c in "wax+"):
            raw = Full(file, mode.replace("t", "").replace("b", "") or "w")
            return raw if "b" in mode else io.TextIOWrapper(io.BufferedWriter(raw), encoding=kwargs.get("encoding"))
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", open_)
    monkeypatch.setattr(io, "open", open_)


@pytest.mark.slow
def test_a_failed_metrics_write_leaves_the_previous_metrics_byte_identical(tiny_cli_run, tmp_path, monkeypatch):
    import shutil

    from jaxmotion.cli import main

    cfg, work = tiny_cli_run
    run = tmp_path / "run"
    shutil.copytree(work, run)
    before = (run / "metrics.json").read_bytes()
    _failing_writes_to(monkeypatch, "metrics")
    with pytest.raises(OSError, match="No space left on device"):
        main(["eval", "--config", str(cfg), "--workdir", str(run)])
    monkeypatch.undo()
    assert (run / "metrics.json").read_bytes() == before
    assert sorted(p.name for p in run.iterdir() if "metrics" in p.name) == ["metrics.json"]  # no temporary left


# --- a checkpoint corrupted on disk is unreadable, not NaN weights ------------------------------------


def _big_fit(workdir: Path, num_steps: int, resume: bool = False):
    """As test_reliability's `_fit`, with arrays large enough (3 x 2000) that orbax stores them outside its
    checksummed b-tree nodes: zstd chunks whose incompressible bytes are stored as they are."""
    from jaxmotion.train.loop import create_state, fit, make_train_step

    w0 = np.random.default_rng(0).normal(size=(3, 2000)).astype(np.float32)
    loss = lambda p, f, b, k: (((b[0] @ p["w"]) ** 2).mean(), {})  # noqa: E731
    return fit(create_state({"w": w0}, TX), make_train_step(loss, TX), _sample, num_steps=num_steps, workdir=workdir,
               seed=3, ckpt_every=5, log_every=5, resume=resume)  # fmt: skip


def _largest_file(step_dir: Path) -> Path:
    """Returns the checkpoint step's largest file: its array data."""
    return max((p for p in step_dir.rglob("*") if p.is_file()), key=lambda p: p.stat().st_size)


def _flip_64_bytes(step_dir: Path) -> None:
    """XORs 1 into 64 bytes in the middle of the checkpoint's largest file (array data).

    Orbax then usually restores other bytes without error; where the bytes land in a compressed
    chunk's framing, TensorStore fails to read the array instead. Either way the checkpoint must not load."""
    f = _largest_file(step_dir)
    data = bytearray(f.read_bytes())
    i = len(data) // 2
    data[i : i + 64] = bytes(b ^ 1 for b in data[i : i + 64])
    f.write_bytes(bytes(data))


# Flipped bits in a float's mantissa change it; in its exponent they may make it NaN or inf; in a
# compressed chunk's framing they make TensorStore's read fail ("Encountered error while reading", or
# "FAILED_PRECONDITION: Error reading" where the chunk's decompression fails).
_CORRUPT = ("its arrays restore to other bytes than were saved|it restores non-finite values|Exception: Encountered error while reading"
            "|FAILED_PRECONDITION: Error reading")


@pytest.fixture
def big_stopped_at_10(tmp_path):
    _big_fit(tmp_path / "run", 10)
    return tmp_path / "run"


def test_a_checkpoint_with_flipped_array_bytes_is_unreadable_and_resume_falls_back(big_stopped_at_10, tmp_path):
    from jaxmotion.errors import CheckpointError
    from jaxmotion.train.loop import restore_untargeted

    run = big_stopped_at_10
    reference = np.asarray(_big_fit(tmp_path / "reference", 15).params["w"])
    _flip_64_bytes(run / "ckpt" / "10")
    with pytest.raises(CheckpointError, match=rf"ckpt: checkpoint step 10 is unreadable: ({_CORRUPT})"):
        restore_untargeted(run / "ckpt")  # what `jaxmotion predict` and `load` use
    with pytest.warns(UserWarning, match=rf"checkpoint step 10 is unreadable \(({_CORRUPT}).*resuming from step 5"):
        resumed = _big_fit(run, 15, resume=True)
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), reference)


def test_a_checkpoint_whose_array_file_is_cut_short_is_refused_naming_its_step(big_stopped_at_10):
    # TensorStore fails to read the array (no bytes to compare): the refusal still names the step.
    from jaxmotion.errors import CheckpointError
    from jaxmotion.train.loop import restore_untargeted

    f = _largest_file(big_stopped_at_10 / "ckpt" / "10")
    f.write_bytes(f.read_bytes()[:16])
    with pytest.raises(CheckpointError, match=r"ckpt: checkpoint step 10 is unreadable: "):
        restore_untargeted(big_stopped_at_10 / "ckpt")


def test_a_finished_stage_with_a_corrupted_last_checkpoint_is_trained_again_from_the_one_before(big_stopped_at_10, tmp_path):
    # The stage counts as finished (step 10 of 10); --resume still checks the checkpoint and falls back.
    from jaxmotion.errors import CheckpointError
    from jaxmotion.train.loop import restore_params

    run = big_stopped_at_10
    _flip_64_bytes(run / "ckpt" / "10")
    state = _big_fit(tmp_path / "unused", 0)
    with pytest.raises(CheckpointError, match=rf"checkpoint step 10 does not restore \(({_CORRUPT})"):
        restore_params(run, state)  # what `jaxmotion eval` uses
    with pytest.warns(UserWarning, match=r"step 10 is unreadable .*resuming from step 5"):
        again = _big_fit(run, 10, resume=True)
    np.testing.assert_array_equal(np.asarray(again.params["w"]), np.asarray(_big_fit(tmp_path / "ref10", 10).params["w"]))


def test_restored_non_finite_values_are_named():
    from jaxmotion.train.loop import CorruptCheckpoint, verify_restored

    verify_restored(Path("/nowhere"), 3, {"a": np.ones(3)})
    with pytest.raises(CorruptCheckpoint, match=r"non-finite values \(NaN/inf\) in \['b'\]\['c'\]"):
        verify_restored(Path("/nowhere"), 3, {"a": np.ones(3), "b": {"c": np.array([1.0, np.nan], np.float32)}})


def _clip(run: Path, path: Path, frames: int = 90) -> Path:
    """Writes an npz clip with the run's joints: a standing pose swaying slowly (metres, the run's frame rate)."""
    import json

    lay = json.loads((run / "predictor.json").read_text())["layout"]
    j = len(lay["joints"])
    rest = np.random.default_rng(0).normal(scale=0.3, size=(j, 3))
    t = np.arange(frames)[:, None, None] / lay["fps"]
    np.savez(path, positions=(rest + 0.05 * np.sin(2 * t + rest)).astype(np.float32), names=np.array(lay["joints"]), fps=lay["fps"])
    return path


@pytest.mark.slow
def test_predict_never_writes_non_finite_futures(tiny_cli_run, tmp_path):
    import jax

    import jaxmotion
    from jaxmotion.errors import CheckpointError
    from jaxmotion.tools.predict_file import predict_file

    _, work = tiny_cli_run
    model = jaxmotion.load(work)
    model.params = jax.tree.map(lambda a: a * np.nan, model.params)  # as a checkpoint without a checksum could restore
    with pytest.raises(CheckpointError, match=r"futures of this input hold NaN or inf .*nothing was written"):
        predict_file(model, _clip(work, tmp_path / "clip.npz"), tmp_path / "out", k=2)
    assert not (tmp_path / "out" / "futures.npz").exists()


# --- valid files that were rejected ------------------------------------------------------------------


def test_c3d_with_nul_padded_units_and_labels_reads_like_the_space_padded_one(tmp_path):
    from c3d_files import c3d_file

    from jaxmotion.formats.c3d import read_c3d

    rng = np.random.default_rng(0)
    points, residual = rng.normal(scale=500, size=(5, 3, 3)), np.zeros((5, 3))
    labels = ["LFHD", "C7", "RTOE"]
    (tmp_path / "spaces.c3d").write_bytes(c3d_file(points, residual, labels, proc=84, scale=-1.0))
    (tmp_path / "nuls.c3d").write_bytes(c3d_file(points, residual, labels, proc=84, scale=-1.0, units=b"mm\x00\x00", pad=b"\x00"))
    a, b = read_c3d(tmp_path / "spaces.c3d"), read_c3d(tmp_path / "nuls.c3d")
    assert b.units == a.units == "mm" and b.labels == a.labels == ("LFHD", "C7", "RTOE")
    np.testing.assert_array_equal(b.points, a.points)


BVH_TWO_JOINTS = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 90 0 0 0 0 0 0 0
0 91 0 0 0 0 0 10 0
"""


def test_bvh_with_a_utf8_byte_order_mark_reads_like_the_one_without(tmp_path):
    from jaxmotion.formats.bvh import read_bvh

    (tmp_path / "plain.bvh").write_text(BVH_TWO_JOINTS)
    (tmp_path / "bom.bvh").write_bytes(b"\xef\xbb\xbf" + BVH_TWO_JOINTS.encode())
    a, b = read_bvh(tmp_path / "plain.bvh"), read_bvh(tmp_path / "bom.bvh")
    assert b.names == a.names == ("Hips", "Chest")
    np.testing.assert_array_equal(b.motion, a.motion)


# --- silent wrong results: named errors instead ------------------------------------------------------


def test_bvh_with_a_joint_name_used_twice_is_a_named_error(tmp_path):
    from jaxmotion.formats.bvh import read_bvh

    twice = BVH_TWO_JOINTS.replace("JOINT Chest", "JOINT Hips")
    (tmp_path / "twice.bvh").write_text(twice)
    with pytest.raises(DataError, match=r"twice\.bvh: HIERARCHY line 5 .*joint name 'Hips' used twice \(first at HIERARCHY line 1\)"):
        read_bvh(tmp_path / "twice.bvh")


def _npz_clip(path: Path, **fields) -> Path:
    pos = np.zeros((40, 3, 3), np.float32)
    pos[:, 1, 1], pos[:, 2, 1] = 0.5, 1.0
    np.savez(path, **{"positions": pos, "names": np.array(["root", "a", "b"]), "fps": 30.0, **fields})
    return path


@pytest.mark.parametrize("fields, problem", [
    ({"scale": -1.0}, r"scale must be a finite number of metres per unit > 0, got -1\.0"),
    ({"scale": np.inf}, r"scale must be a finite number of metres per unit > 0, got inf"),
    ({"fps": np.nan}, r"frame rate must be a finite number > 0, got nan"),
    ({"fps": 0.0}, r"frame rate must be a finite number > 0, got 0\.0"),
    ({"fps": -30.0}, r"frame rate must be a finite number > 0, got -30\.0"),
    ({"up_axis": 5}, r"'up_axis' must be 0, 1 or 2 \(x, y or z\), got 5"),
    ({"up_axis": 1.5}, r"'up_axis' must be 0, 1 or 2 \(x, y or z\), got 1\.5"),
    ({"names": np.array(["root", "a", "a"])}, r"joint names used twice: \['a'\]"),
], ids=["negative_scale", "inf_scale", "nan_fps", "zero_fps", "negative_fps", "up_axis_5", "up_axis_1.5", "duplicate_names"])
def test_npz_clip_fields_that_would_silently_mislead_are_named_errors(tmp_path, fields, problem):
    from jaxmotion.tools.predict_file import read_motion

    with pytest.raises(DataError, match=r"clip\.npz: " + problem):
        read_motion(_npz_clip(tmp_path / "clip.npz", **fields))


def test_a_negative_scale_argument_is_a_named_error(tmp_path):
    from jaxmotion.tools.predict_file import read_motion

    (tmp_path / "c.bvh").write_text(BVH_TWO_JOINTS)
    with pytest.raises(DataError, match=r"c\.bvh: scale must be .* > 0, got -1"):
        read_motion(tmp_path / "c.bvh", scale=-1.0)


def test_config_attribute_typo_is_a_config_error_naming_the_line(tmp_path):
    from jaxmotion.config import load_config
    from jaxmotion.errors import ConfigError

    path = tmp_path / "typo.py"
    path.write_text("from jaxmotion.config import Config\nfrom jaxmotion.models.dlow import DLowConfig\n\n"
                    "def get_config():\n    c = Config(method_config=DLowConfig())\n    c.ckpt_every = 7\n"
                    "    c.method_config.cvae.num_stpes = 3\n    return c\n")
    with pytest.raises(ConfigError, match=r"typo\.py: line 7: unknown field 'num_stpes' of CVAEConfig; did you mean 'num_steps'\?"):
        load_config(path)
    path.write_text("def get_config():\n    return {'name': 'x'}\n")
    with pytest.raises(ConfigError, match=r"get_config\(\) returned a dict, expected a jaxmotion.config.Config"):
        load_config(path)
    path.write_text("x = 1\n")
    with pytest.raises(ConfigError, match=r"must define get_config\(\)"):
        load_config(path)


# --- resource bombs: limits with named errors ----------------------------------------------------------


def test_a_frame_rate_that_would_resample_to_millions_of_frames_is_refused_before_allocating(tmp_path):
    from jaxmotion.data.windows import resample

    with pytest.raises(DataError, match=r"clip\.bvh: resampling 100 frames from 0\.001 to 30 fps gives 2970001 frames .*limits are 1000000 frames and 1 GiB"):
        resample(np.zeros((100, 21, 3)), 0.001, 30.0, "clip.bvh")
    with pytest.raises(DataError, match=r"clip\.npz: input frame rate must be a finite number > 0, got 0\.0"):
        resample(np.zeros((100, 21, 3)), 0.0, 30.0, "clip.npz")
    assert resample(np.zeros((100, 21, 3)), 60.0, 30.0).shape == (50, 21, 3)


@pytest.mark.parametrize("frame_time", ["1000", "999999", "1e-6", "0"])
def test_bvh_frame_time_outside_capture_rates_is_a_named_error(tmp_path, frame_time):
    from jaxmotion.formats.bvh import read_bvh

    (tmp_path / "ft.bvh").write_text(BVH_TWO_JOINTS.replace("Frame Time: 0.0333333", f"Frame Time: {frame_time}"))
    with pytest.raises(DataError, match=r"ft\.bvh: Frame Time must be a positive number of seconds \(1e-05 to 60"):
        read_bvh(tmp_path / "ft.bvh")


def _chain_bvh(joints: int) -> str:
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    for j in range(1, joints):
        lines += [f"JOINT j{j}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * joints
    return "\n".join(lines + ["MOTION", "Frames: 1", "Frame Time: 0.0333333", " ".join(["0"] * 3 * joints)]) + "\n"


def test_a_10000_joint_chain_is_a_named_error_and_a_long_chain_writes_without_recursion(tmp_path):
    from jaxmotion.formats.bvh import MAX_JOINTS, forward_kinematics, read_bvh
    from jaxmotion.formats.bvh_write import write_bvh

    (tmp_path / "chain.bvh").write_text(_chain_bvh(10_000))
    with pytest.raises(DataError, match=rf"chain\.bvh: .*more than {MAX_JOINTS} joints"):
        read_bvh(tmp_path / "chain.bvh")
    (tmp_path / "long.bvh").write_text(_chain_bvh(MAX_JOINTS))  # deeper than Python's recursion limit
    bvh = read_bvh(tmp_path / "long.bvh")
    again = read_bvh(write_bvh(tmp_path / "again.bvh", bvh))
    assert again.parents == bvh.parents and again.names == bvh.names
    np.testing.assert_allclose(forward_kinematics(again)[0, -1], [0, MAX_JOINTS - 1, 0], atol=1e-9)


# --- the command line: one message, exit code 2, no traceback (each in its own process) ------------------

REPO = Path(__file__).resolve().parents[1]


def _cli(*args: str, cwd: Path | None = None, timeout: int = 300):
    """Runs `python -m jaxmotion.cli ARGS` (this checkout); returns the completed process."""
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([sys.executable, "-m", "jaxmotion.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=cwd)


def _one_error_line(r, pattern: str) -> str:
    """Asserts exit code 2 and a stderr of one line (argparse: usage, then one) matching `pattern`, no traceback."""
    import re

    err = r.stderr.strip()
    assert r.returncode == 2, (r.returncode, err[-3000:])
    assert "Traceback" not in err and "Event loop is closed" not in err, err[-3000:]
    lines = [line for line in err.splitlines() if not line.startswith(("usage:", "  "))]
    assert len(lines) == 1, err[-3000:]
    assert re.search(pattern, lines[0]), lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def run_copy(tiny_cli_run, tmp_path_factory):
    """Returns `(config file, make)`: `make(name)` copies the session's tiny trained run into a fresh folder."""
    import shutil

    cfg, work = tiny_cli_run
    base = tmp_path_factory.mktemp("runs")

    def make(name: str) -> Path:
        shutil.copytree(work, base / name, ignore=shutil.ignore_patterns(".jaxmotion*"))
        return base / name

    return cfg, make


@pytest.mark.slow
def test_eval_on_an_unreadable_checkpoint_prints_one_line(run_copy):
    cfg, make = run_copy
    run = make("unreadable")
    step = max((run / "cvae" / "ckpt").iterdir(), key=lambda p: int(p.name) if p.name.isdigit() else -1)
    for f in step.rglob("*"):
        if f.is_file() and f.parent.name == "d":
            f.write_bytes(f.read_bytes()[:10])
    _one_error_line(_cli("eval", "--config", cfg, "--workdir", run),
                    rf"^jaxmotion: error: stage 'cvae' of method 'dlow': .*ckpt: checkpoint step {step.name} does not restore")


@pytest.mark.slow
@pytest.mark.parametrize("command", ["eval", "sample", "train"])
def test_a_read_only_run_folder_is_one_line_naming_it(run_copy, command):
    from test_reliability import read_only

    cfg, make = run_copy
    run = make(f"read_only_{command}")
    (run / ".jaxmotion.lock").write_text("")  # as a run that held the lock leaves it
    extra = ["--resume"] if command == "train" else []
    with read_only(run):
        r = _cli(command, "--config", cfg, "--workdir", run, *extra)
    _one_error_line(r, rf"^jaxmotion: error: {run}: cannot write to the run folder \((PermissionError|OSError)")
    assert not (run / "metrics.json").read_bytes() == b""


@pytest.mark.slow
def test_a_second_process_on_a_run_folder_gets_the_lock_error_and_a_dead_holders_lock_is_taken_over(run_copy, tmp_path):
    import signal
    import subprocess
    import sys

    from jaxmotion.train.run_lock import LOCK_FILE, run_lock

    cfg, make = run_copy
    run = make("locked")
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from jaxmotion.train.run_lock import run_lock\n"
                               "with run_lock(sys.argv[1], 'train'):\n    print('held', flush=True); time.sleep(600)", str(run)],
                              stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        assert holder.stdout.readline().strip() == "held"
        _one_error_line(_cli("train", "--config", cfg, "--workdir", run, "--resume"),
                        rf"^jaxmotion: error: {run}: in use by another jaxmotion process \(pid {holder.pid} on \S+, lock file {LOCK_FILE}\)")
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert (run / LOCK_FILE).read_text().startswith(f"{holder.pid} ")  # a killed holder leaves its pid behind
    with run_lock(run):  # ... and its lock is free: taken over
        assert (run / LOCK_FILE).read_text().startswith(f"{os.getpid()} ")


@pytest.mark.slow
def test_predict_errors_are_one_line_each(run_copy, tmp_path):
    import json

    _, make = run_copy
    run = make("predict")
    clip = _clip(run, tmp_path / "clip.npz")
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    cases = [
        (["--frame", "100000"], r"--frame must be in \[0, 90\) for .*clip\.npz \(90 frames\), got 100000"),
        (["--method", "nope"], r"predict: method 'nope' at K=\d+ is not available; available: \["),
        (["--k", "0"], r"argument --k: must be in \[1, 2147483647\], got 0"),
        (["--seed", "-1"], r"argument --seed: must be in \[0, 4294967295\], got -1"),
        (["--scale", "-1"], r"argument --scale: must be a finite number > 0, got -1"),
    ]
    for extra, pattern in cases:
        _one_error_line(_cli("predict", run, "--input", clip, "--out", tmp_path / "o", *extra), pattern)
    _one_error_line(_cli("predict", run, "--input", clip, "--out", a_file), r"--out .*a_file is a file; give a folder")
    z = dict(np.load(clip))
    np.savez(tmp_path / "fps0.npz", **{**z, "fps": 0.0})
    _one_error_line(_cli("predict", run, "--input", tmp_path / "fps0.npz", "--out", tmp_path / "o"),
                    r"fps0\.npz: frame rate must be a finite number > 0, got 0\.0")
    assert not (tmp_path / "o" / "futures.npz").exists()
    empty = make("empty_ckpt")
    for f in (empty / "cvae" / "ckpt").iterdir():
        import shutil

        shutil.rmtree(f)
    _one_error_line(_cli("predict", empty, "--input", clip, "--out", tmp_path / "o"), r"cvae/ckpt: no checkpoint; train this run first")
    cut = make("cut_manifest")
    text = (cut / "predictor.json").read_text()
    (cut / "predictor.json").write_text(text[: len(text) // 2])
    _one_error_line(_cli("predict", cut, "--input", clip, "--out", tmp_path / "o"),
                    r"predictor\.json: unreadable \(JSONDecodeError: .*`jaxmotion eval` on the run writes it again")
    json.loads(text)  # the original was whole


@pytest.mark.slow
def test_config_and_option_errors_are_one_line_each(tmp_path):
    cfg = tmp_path / "c.py"
    cases = [
        ("from jaxmotion.config import Config\ndef get_config():\n    return Config(method='nope')\n", [],
         r"c\.py: .*unknown method 'nope'"),  # one problem: one line
        ("def get_config():\n    return {'name': 'x'}\n", [], r"c\.py: get_config\(\) returned a dict"),
        ("from jaxmotion.config import Config\ndef get_config():\n    return Config()\n", ["--seed", "-1"],
         r"argument --seed: must be in \[0, 4294967295\], got -1"),
    ]
    for text, extra, pattern in cases:
        cfg.write_text(text)
        r = _cli("train", "--config", cfg, "--workdir", tmp_path / "w", *extra)
        err = r.stderr.strip()
        assert r.returncode == 2 and "Traceback" not in err, err[-3000:]
        assert any(__import__("re").search(pattern, line) for line in err.splitlines()), err
    cfg.write_text("from jaxmotion.config import Config\ndef get_config():\n    return Config(method='nope')\n")
    assert "unknown method 'nope'; registered: [" in _cli("eval", "--config", cfg).stderr


def test_stderr_filter_drops_only_late_event_loop_tracebacks():
    import io
    import traceback

    from jaxmotion.cli import _LateLoopTracebacksDropped

    def printed(raise_) -> str:
        try:
            raise_()
        except Exception as e:
            return "".join(traceback.format_exception(e))

    import asyncio

    loop = asyncio.new_event_loop()
    loop.close()
    late = printed(lambda: loop.call_soon_threadsafe(print))
    other = printed(lambda: 1 / 0)
    out = io.StringIO()
    f = _LateLoopTracebacksDropped(out)
    for text in ("before\n", late, "progress\r", other, "after\n"):
        for piece in text.splitlines(keepends=True):  # as the interpreter prints a traceback: a line at a time
            f.write(piece)
    assert out.getvalue() == "before\nprogress\r" + other + "after\n"

    # Two threads' late tracebacks interleaved line by line (as tensorstore's threads print them): both dropped.
    import threading

    out = io.StringIO()
    f = _LateLoopTracebacksDropped(out)
    lines = late.splitlines(keepends=True)
    step = [threading.Barrier(2) for _ in lines]

    def print_late():
        for line, barrier in zip(lines, step):
            barrier.wait()
            f.write(line)

    threads = [threading.Thread(target=print_late) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    f.write("jaxmotion: error: the message\n")
    assert out.getvalue() == "jaxmotion: error: the message\n"


@pytest.mark.slow
def test_a_joint_that_cannot_rotate_is_one_line_and_nothing_is_written(run_copy, tmp_path):
    import dataclasses

    from jaxmotion.data.synthetic import make_synthetic
    from jaxmotion.formats.bvh_write import write_bvh
    from jaxmotion.tools.retarget import bvh_from_positions

    _, make = run_copy
    run = make("channels0")
    ds = make_synthetic(0)
    b = bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, ds.test[0].positions[:120], ds.fps)
    j = b.names.index("LKnee")
    start, n = b.channel_starts[j], len(b.channels[j])
    channels = tuple(() if i == j else c for i, c in enumerate(b.channels))
    clip = write_bvh(tmp_path / "ch0.bvh", dataclasses.replace(b, channels=channels, motion=np.delete(b.motion, range(start, start + n), axis=1)))
    lines = clip.read_text().splitlines()
    at = lines.index("\t\tJOINT LKnee") + 3  # after its '{' and OFFSET: the writer leaves out an empty CHANNELS line
    clip.write_text("\n".join(lines[:at] + ["\t\t\tCHANNELS 0"] + lines[at:]) + "\n")
    _one_error_line(_cli("predict", run, "--input", clip, "--out", tmp_path / "o"),
                    r"ch0\.bvh: the futures cannot be written on this skeleton \(.*joint 'LKnee' has no rotation channels.*nothing was written")
    assert not any((tmp_path / "o").glob("*"))
