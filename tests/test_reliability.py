"""Reliability: corrupt checkpoints, failed writes, BVH folders, NaN at load, config validation.

The kill-and-resume tests of `jaxmotion train` as a subprocess are in `test_kill_resume.py`.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import optax
import pytest

from jaxmotion.config import Config, validate
from jaxmotion.data.datasets import load_bvh_folder, load_dataset
from jaxmotion.errors import CheckpointError, ConfigError, DataError
from jaxmotion.formats.bvh import read_bvh
from jaxmotion.train.loop import create_state, fit, make_train_step, restore_params

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
CMU_DIR = SHARED_DATA / "cmu-bvh"

W_TRUE = np.array([[1.0, -2.0], [0.5, 3.0], [2.0, 0.0]], np.float32)
TX = optax.adam(0.05)


def _loss(params, frozen, batch, key):
    x, y = batch
    err = ((x @ params["w"] - y) ** 2).mean()
    return err, {"mse": err}


def _sample(rng):
    x = rng.normal(size=(8, 3)).astype(np.float32)
    return x, x @ W_TRUE


def _state():
    import jax.numpy as jnp

    return create_state({"w": jnp.zeros((3, 2))}, TX)


def _fit(workdir: Path, num_steps: int, resume: bool = False):
    return fit(_state(), make_train_step(_loss, TX), _sample, num_steps=num_steps, workdir=workdir, seed=3,
               ckpt_every=5, log_every=5, resume=resume)  # fmt: skip


def _log(workdir: Path) -> list[tuple[int, float]]:
    return [(r["step"], r["loss"]) for r in map(json.loads, (workdir / "log.jsonl").read_text().splitlines())]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Returns an uninterrupted 15-step run's folder and parameters."""
    d = tmp_path_factory.mktemp("reference")
    return d, np.asarray(_fit(d, 15).params["w"])


@pytest.fixture
def stopped_at_10(tmp_path):
    """Returns a folder trained to step 10 (checkpoints 5 and 10), as if the 15-step run had been killed."""
    _fit(tmp_path / "run", 10)
    return tmp_path / "run"


def _steps(ckpt: Path) -> list[int]:
    return sorted(int(p.name) for p in ckpt.iterdir() if p.name.isdigit())


def _data_files(step_dir: Path) -> list[str]:
    return glob.glob(str(step_dir / "default" / "**" / "d" / "*"), recursive=True)


def _truncate(step_dir: Path):
    for f in _data_files(step_dir):
        Path(f).write_bytes(Path(f).read_bytes()[:10])


def _drop_metadata(step_dir: Path):
    (step_dir / "default" / "_METADATA").unlink()


def _zero(step_dir: Path):
    for f in _data_files(step_dir):
        Path(f).write_bytes(bytes(Path(f).stat().st_size))


def _empty(step_dir: Path):  # the folder exists, nothing was written into it yet
    shutil.rmtree(step_dir)
    step_dir.mkdir()


CORRUPTIONS = {"truncated": _truncate, "no_metadata": _drop_metadata, "zeroed": _zero, "empty": _empty}


@pytest.mark.parametrize("kind", sorted(CORRUPTIONS))
def test_resume_falls_back_past_an_unreadable_latest_checkpoint(stopped_at_10, reference, kind):
    ref_dir, ref_w = reference
    CORRUPTIONS[kind](stopped_at_10 / "ckpt" / "10")
    with pytest.warns(UserWarning, match=r"checkpoint step 10 is unreadable .*resuming from step 5.*nothing deleted"):
        resumed = _fit(stopped_at_10, 15, resume=True)
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), ref_w)  # bitwise: same batches and keys
    assert _log(stopped_at_10) == _log(ref_dir)  # steps 5, 10, 15 once each, the same losses
    assert (stopped_at_10 / "ckpt.unreadable" / "10").is_dir()  # moved aside, not deleted
    assert (stopped_at_10 / "log.replaced.jsonl").read_text().count('"step": 10') == 1


def test_no_usable_checkpoint_is_a_clear_error_and_deletes_nothing(stopped_at_10):
    for step in (5, 10):
        _truncate(stopped_at_10 / "ckpt" / str(step))
    before = sorted(p.name for p in (stopped_at_10 / "ckpt").iterdir())
    with pytest.raises(CheckpointError, match=r"no checkpoint restores \(step 10: .*; step 5: .*\); nothing was deleted"):
        _fit(stopped_at_10, 15, resume=True)
    assert sorted(p.name for p in (stopped_at_10 / "ckpt").iterdir()) == before == ["10", "5"]


def test_restoring_an_unreadable_checkpoint_names_the_step(stopped_at_10):
    _drop_metadata(stopped_at_10 / "ckpt" / "10")
    with pytest.raises(CheckpointError, match=re.escape(str(stopped_at_10 / "ckpt")) + ": checkpoint step 10 does not restore"):
        restore_params(stopped_at_10, _state())


def test_kill_during_a_checkpoint_write_resumes_from_the_one_before(stopped_at_10, reference):
    # Orbax writes a step into a temporary folder and renames it when complete; a kill leaves the temporary one,
    # which it replaces when it writes that step again.
    ckpt = stopped_at_10 / "ckpt"
    os.rename(ckpt / "10", ckpt / "10.orbax-checkpoint-tmp")
    with open(stopped_at_10 / "log.jsonl", "a") as f:
        f.write('{"stage": "train", "step": 1')  # and a log line cut short
    resumed = _fit(stopped_at_10, 15, resume=True)
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), reference[1])
    assert _log(stopped_at_10) == _log(reference[0])
    assert _steps(ckpt) == [10, 15]


@contextlib.contextmanager
def read_only(folder: Path):
    """Makes `folder` unwritable: chmod for a user, the immutable attribute for root (skips when neither works)."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(0o755)
        return
    if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode:
        pytest.skip("running as root without `chattr +i`: cannot make a folder read-only")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


def test_read_only_checkpoint_folder_reports_the_path_and_keeps_the_checkpoints(stopped_at_10):
    ckpt = stopped_at_10 / "ckpt"
    with read_only(ckpt):
        with pytest.raises(CheckpointError, match=re.escape(str(ckpt)) + r": cannot write checkpoint.*kept there: steps \[5, 10\]"):
            _fit(stopped_at_10, 15, resume=True)
    assert sorted(p.name for p in ckpt.iterdir() if p.name.isdigit()) == ["10", "5"]
    assert int(restore_params(stopped_at_10, _state()).step) == 10


def test_full_disk_reports_the_path_and_keeps_the_checkpoints(tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=160k", "tmpfs", str(mnt)], capture_output=True).returncode:
        pytest.skip("needs root and mount to make a small tmpfs")
    try:
        # Checkpoints of a 3 x 2000 parameter matrix and its Adam moments (about 72 kB each) soon fill 160 kB.
        big = lambda: create_state({"w": np.zeros((3, 2000), np.float32)}, TX)  # noqa: E731
        loss = lambda p, f, b, k: (((b[0] @ p["w"]) ** 2).mean(), {})  # noqa: E731
        pattern = re.escape(str(mnt / "ckpt")) + r": cannot write checkpoint step (\d+) \(.*(?:No space|RESOURCE_EXHAUSTED).*kept there: steps \[(.+)\]"
        with pytest.raises(CheckpointError, match=pattern) as e:
            fit(big(), make_train_step(loss, TX), _sample, num_steps=40, workdir=mnt, seed=0, ckpt_every=1, log_every=1)
        failed, kept = re.search(pattern, str(e.value)).groups()  # the write that fails depends on file sizes
        kept = [int(k) for k in kept.split(", ")]
        assert kept and max(kept) == int(failed) - 1
        assert int(restore_params(mnt, big()).step) == max(kept)  # the one before the failed write restores
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


# --- BVH folders: the root decided once per folder ------------------------------------------------


def _with_ground_root(src: Path, dst: Path, carries_walk: bool, frames: int = 240) -> None:
    """Writes the first `frames` of `src` below a zero-offset root `Ground` (3 position channels).

    With `carries_walk` the Ground node carries the hips' translation (the hips' position channels
    become 0), as an exporter does in clips where the root carries the walk; else Ground stays at 0.
    """
    lines = src.read_text().splitlines()
    m = lines.index("MOTION")
    hier = lines[1:m]  # without "HIERARCHY"
    hier[0] = hier[0].replace("ROOT", "JOINT")
    rows = [r.split() for r in lines[m + 3 : m + 3 + frames]]
    out = []
    for r in rows:
        walk, r = r[:3], list(r)
        if carries_walk:
            r[:3] = ["0", "0", "0"]
        out.append(" ".join((walk if carries_walk else ["0", "0", "0"]) + r))
    text = ["HIERARCHY", "ROOT Ground", "{", "OFFSET 0 0 0", "CHANNELS 3 Xposition Yposition Zposition", *hier, "}",
            "MOTION", f"Frames: {frames}", lines[m + 2], *out]  # fmt: skip
    dst.write_text("\n".join(text) + "\n")


def test_bvh_folder_decides_the_root_once_for_an_exporter_whose_root_sometimes_walks(tmp_path):
    if not (CMU_DIR / "01_01.bvh").is_file():
        pytest.skip(f"shared data not found at {CMU_DIR}")
    folder = tmp_path / "exporter"
    folder.mkdir()
    _with_ground_root(CMU_DIR / "01_01.bvh", folder / "01_01.bvh", carries_walk=False)
    _with_ground_root(CMU_DIR / "01_03.bvh", folder / "01_03.bvh", carries_walk=True)
    ds = load_bvh_folder(folder)
    assert ds.skeleton.names[0] == "Hips" and ds.skeleton.num_joints == 31
    # Dropping the ground node leaves exactly the original CMU positions, whichever node carried the walk.
    plain = tmp_path / "plain"
    plain.mkdir()
    for name in ("01_01.bvh", "01_03.bvh"):
        lines = (CMU_DIR / name).read_text().splitlines()
        m = lines.index("MOTION")
        (plain / name).write_text("\n".join(lines[: m + 1] + ["Frames: 240"] + lines[m + 2 : m + 3 + 240]) + "\n")
    ref = load_bvh_folder(plain)
    assert ref.skeleton == ds.skeleton
    for a, b in zip(ds.test, ref.test):
        np.testing.assert_allclose(a.positions, b.positions, atol=1e-5)
    # The user may name the root instead; joints above it must be a chain.
    assert load_bvh_folder(folder, root="Hips").skeleton == ds.skeleton
    with pytest.raises(ValueError, match=r"root='LeftUpLeg'.*joint 'Hips' above it .* has children"):
        load_bvh_folder(folder, root="LeftUpLeg")
    with pytest.raises(ValueError, match="root='Nope' is not a joint"):
        load_bvh_folder(folder, root="Nope")


def test_bvh_folder_with_two_skeletons_names_both_files(tmp_path):
    if not (CMU_DIR / "01_01.bvh").is_file():
        pytest.skip(f"shared data not found at {CMU_DIR}")
    _with_ground_root(CMU_DIR / "01_01.bvh", tmp_path / "a.bvh", carries_walk=True, frames=10)
    lines = (CMU_DIR / "01_03.bvh").read_text().splitlines()
    m = lines.index("MOTION")
    (tmp_path / "b.bvh").write_text("\n".join(lines[: m + 1] + ["Frames: 10"] + lines[m + 2 : m + 13]) + "\n")
    with pytest.raises(DataError, match=r"b\.bvh: skeleton differs from .*a\.bvh's: joints \['\w+'\] missing \(31 vs 32 joints\)"):
        load_bvh_folder(tmp_path)


# --- NaN and inf at load, with file and frame -------------------------------------------------------

BVH = """HIERARCHY
ROOT A
{
OFFSET 0 0 0
CHANNELS 3 Xposition Yposition Zposition
JOINT B
{
OFFSET 0 100 0
CHANNELS 3 Zrotation Xrotation Yrotation
End Site
{
OFFSET 0 50 0
}
}
}
MOTION
Frames: 3
Frame Time: 0.04
0 0 0 0 0 0
0 0 0 10 0 0
0 0 0 20 0 0
"""


def test_nan_in_bvh_names_file_frame_and_channel(tmp_path):
    path = tmp_path / "nan.bvh"
    path.write_text(BVH.replace("0 0 0 10 0 0", "0 0 0 10 nan 0"))
    with pytest.raises(DataError, match=r"nan\.bvh: non-finite value nan at frame 1 \(motion row 1\), channel B:Xrotation"):
        read_bvh(path)


def test_nan_in_npz_names_file_frame_and_joint(tmp_path):
    t = np.repeat(np.linspace(0.5, 1.2, 15 * 3, dtype=np.float32).reshape(1, 15, 3), 4, 0)  # a person's size
    data = {s: {"Walking": t.copy()} for s in ("Train/S1", "Train/S2", "Train/S3", "Validate/S1", "Validate/S2", "Validate/S3")}
    data["Validate/S2"]["Walking"][2, 7, 0] = np.inf
    path = tmp_path / "humaneva.npz"
    np.savez(path, positions_3d=np.array(data, dtype=object))
    with pytest.raises(DataError, match=r"humaneva\.npz: positions_3d\['Validate/S2'\]\['Walking'\]: non-finite value inf at frame 2, joint 7"):
        load_dataset(path)


# --- config validation --------------------------------------------------------------------------------


def test_config_validation_lists_every_problem():
    from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig

    q = QConfig(lr=-1e-4)
    object.__setattr__(q, "nh_mlp", (32, "64"))  # past the test suite's type-checking hook, as a user's config gets
    cfg = Config(ckpt_every=0, eval_k=(50, 0), train_sampler="every",
                 method_config=DLowConfig(cvae=CVAEConfig(num_steps=-5, batch_size=0), q=q))  # fmt: skip
    object.__setattr__(cfg, "seed", "0")
    with pytest.raises(ConfigError) as e:
        validate(cfg)
    problems = e.value.problems
    assert len(problems) == 8, problems
    msg = str(e.value)
    for text in ("ckpt_every must be >= 1, got 0", "eval_k must be >= 1 each, got (50, 0)", "seed must be int, got str '0'",
                 "train_sampler must be one of", "method_config.cvae.num_steps must be >= 0, got -5",
                 "method_config.cvae.batch_size must be >= 1, got 0", "method_config.q.lr must be > 0, got -0.0001",
                 "method_config.q.nh_mlp must be tuple[int, ...], got tuple (32, '64')"):  # fmt: skip
        assert text in msg, msg
    validate(Config())  # the defaults are valid


def test_unknown_config_fields_are_listed(tmp_path):
    from jaxmotion.config import load_config

    path = tmp_path / "typo.py"
    path.write_text("from jaxmotion.config import Config\ndef get_config():\n    return Config(nmae='x', ckpt_evry=10)\n")
    with pytest.raises(ConfigError, match=r"(?s)typo\.py: 2 problems.*unknown field 'nmae'.*unknown field 'ckpt_evry'.*ckpt_every"):
        load_config(path)


def test_batch_larger_than_the_data_is_a_config_error():
    from jaxmotion.models.dlow import CVAEConfig, DLowConfig

    cfg = Config(method_config=DLowConfig(cvae=CVAEConfig(batch_size=500)))
    with pytest.raises(ConfigError, match=r"method_config.cvae.batch_size 500 is larger than the 400 training windows"):
        validate(cfg, num_train_windows=400)


def test_console_script_prints_user_errors_without_a_traceback(tmp_path):
    import subprocess
    import sys

    cfg = tmp_path / "typo.py"
    cfg.write_text("from jaxmotion.config import Config\n\ndef get_config():\n    return Config(name='t', ckpt_evry=5)\n")
    code = "import sys; from jaxmotion.cli import entry; sys.argv = ['jaxmotion'] + sys.argv[1:]; sys.exit(entry())"
    r = subprocess.run([sys.executable, "-c", code, "train", "--config", str(cfg), "--workdir", str(tmp_path / "run")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert "unknown field 'ckpt_evry' of Config; did you mean 'ckpt_every'?" in r.stderr
    assert str(cfg) in r.stderr
