"""A careless or hostile user's inputs, each pinned to one named error (or to the right result).

Files: every reader passes its positions through `data.plausible.check_positions` (real floats, finite,
a person's size after units) and honours or refuses a declared axis. Configs and options: widths,
K, seeds and counts are checked before any data is read, and the largest allocation of evaluation
and training is estimated from the config and the data's shapes before a step is trained.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.config import Config, check_memory, load_config, memory_estimate, validate
from jaxmotion.errors import ConfigError, DataError, UsageError
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig

from c3d_files import c3d_file

REPO = Path(__file__).resolve().parents[1]


def _body(frames: int = 6, joints: int = 5) -> np.ndarray:
    """Returns `(frames, joints, 3)` float64 positions of a body 1.2 m tall (joints up a vertical line)."""
    column = np.stack([np.zeros(joints), np.linspace(0.0, 1.2, joints), np.zeros(joints)], -1)
    return np.repeat(column[None], frames, 0) + np.linspace(0, 0.1, frames)[:, None, None]


# --- files: one plausibility check shared by every reader -------------------------------------------


@pytest.mark.parametrize("edit, match", [
    ("complex", r"'positions' must hold real floating-point numbers \(metres\), got dtype complex128"),
    ("bool", r"'positions' must hold real floating-point numbers \(metres\), got dtype bool"),
    ("huge", r"'positions': a body 1\.2e\+30 m across .*not a person's 0\.5-2\.6 m; wrong units\?"),
    ("scale", r"'positions': a body 1\.2e\+06 m across .*\(1e\+06 m per unit\), not a person's"),
])  # fmt: skip
def test_an_npz_clip_that_is_no_person_in_metres_is_refused(tmp_path, edit, match):
    from jaxmotion.tools.predict_file import read_motion

    pos = {"complex": _body() + 1j, "bool": _body() > 0.5, "huge": _body() * 1e30, "scale": _body()}[edit]
    extra = {"scale": np.array(1e6)} if edit == "scale" else {}
    path = tmp_path / "clip.npz"
    np.savez(path, positions=pos, **extra)
    with pytest.raises(DataError, match=match):
        read_motion(path)


def test_a_plausible_npz_clip_is_read_in_metres(tmp_path):
    from jaxmotion.tools.predict_file import read_motion

    path = tmp_path / "clip.npz"
    np.savez(path, positions=_body() * 100, scale=np.array(0.01))
    np.testing.assert_allclose(read_motion(path).positions, _body(), rtol=1e-6)


def test_a_c3d_whose_units_say_m_but_hold_mm_is_refused(tmp_path):
    from jaxmotion.tools.predict_file import read_motion

    mm = (_body(frames=4, joints=8) * 1000).astype(np.float32)
    labels = [f"M{i}" for i in range(8)]
    path = tmp_path / "walk.c3d"
    path.write_bytes(c3d_file(mm, np.zeros(mm.shape[:2]), labels, proc=84, scale=-1.0, units=b"m"))
    with pytest.raises(DataError, match=r"walk\.c3d: marker positions: a body 1\.2e\+03 m across .*POINT:UNITS says m"):
        read_motion(path)
    path.write_bytes(c3d_file(mm, np.zeros(mm.shape[:2]), labels, proc=84, scale=-1.0, units=b"mm"))
    assert read_motion(path).positions.shape == (4, 8, 3)  # the same numbers in mm are a person


def test_a_bvh_without_frames_is_one_named_error(tmp_path):
    from jaxmotion.data.datasets import load_bvh_folder
    from jaxmotion.tools.predict_file import read_motion

    from test_reliability import BVH  # a two-joint BVH

    head, _, _ = BVH.partition("MOTION")
    for name in ("a.bvh", "b.bvh"):
        (tmp_path / name).write_text(head + "MOTION\nFrames: 0\nFrame Time: 0.033333\n")
    with pytest.raises(DataError, match=r"a\.bvh: 'Frames: 0': a skeleton without motion"):
        load_bvh_folder(tmp_path)
    with pytest.raises(DataError, match=r"a\.bvh: 'Frames: 0'"):
        read_motion(tmp_path / "a.bvh")


def test_a_text_file_named_npz_gets_no_advice_to_unpickle(tmp_path):
    from jaxmotion.data.datasets import load_dataset
    from jaxmotion.tools.predict_file import read_motion

    path = tmp_path / "clip.npz"
    path.write_text("positions\n1 2 3\n")
    for read in (read_motion, load_dataset):
        with pytest.raises(DataError, match=r"clip\.npz: not an npz file") as e:
            read(path)
        assert "pickle" not in str(e.value)


# --- configs: checked before data is read, sized before a step is trained ----------------------------


def _dlow(**cvae) -> Config:
    return Config(method_config=DLowConfig(cvae=CVAEConfig(**cvae), q=QConfig()))


@pytest.mark.parametrize("cfg, match", [
    (_dlow(nh_rnn=0), r"method_config\.cvae\.nh_rnn \(a layer width\) must be >= 1, got 0"),
    (_dlow(nh_mlp=(300, 0)), r"method_config\.cvae\.nh_mlp \(layer widths\) must be >= 1 each, got \(300, 0\)"),
    (Config(eval_k=(5, 5)), r"eval_k must be distinct values \(each K is one evaluation record\), got \(5, 5\)"),
    (Config(seed=2**64), r"seed must be in \[0, 2\*\*32\)"),
])  # fmt: skip
def test_impossible_settings_are_named_before_anything_runs(cfg, match):
    with pytest.raises(ConfigError, match=match):
        validate(cfg)


@pytest.mark.parametrize("change, what", [
    ({"method_config": DLowConfig(cvae=CVAEConfig(nh_rnn=10**6), q=QConfig())}, r"training \(CVAEConfig\): the widest layer's weights \(1000000\)"),
    ({"eval_batch": 10**9}, r"evaluation: eval_batch 1000000000 x K 50 futures"),
    ({"eval_batch": 10**6}, r"evaluation: eval_batch 1000000 x K 50 futures"),
    ({"eval_k": (10**6,)}, r"evaluation: APD's eval_batch 64 x K 1000000 x K 1000000 distances"),
])  # fmt: skip
def test_a_config_past_this_machines_memory_is_refused_with_its_estimate(change, what):
    cfg = dataclasses.replace(Config(), **change)
    validate(cfg)  # each is a valid config: only its size is wrong
    with pytest.raises(ConfigError, match=what + r".* need about [\d,]+ GiB at once, more than (this machine's RAM|.*memory) \(\d+ GiB\)"):
        check_memory(cfg, dim=42, t_his=15, t_pred=60)


def test_the_shipped_configs_fit_this_machine():
    limit = 16 * 2**30  # a laptop
    for path in sorted((REPO / "experiments" / "configs").glob("*.py")):
        from jaxmotion import experiment

        cfg = experiment.resolve(load_config(path))
        biggest = max(memory_estimate(cfg, dim=66, t_his=25, t_pred=100).values())
        assert biggest < limit, (path.name, biggest / 2**30)


def test_a_config_file_is_python_whatever_its_name(tmp_path):
    source = "from jaxmotion.config import Config\n\ndef get_config():\n    return Config(name='from_txt', seed=3)\n"
    path = tmp_path / "my_config.txt"
    path.write_text(source)
    assert (load_config(path).name, load_config(path).seed) == ("from_txt", 3)
    path.write_text("this is not python\n")
    with pytest.raises(ConfigError, match=r"my_config\.txt: .*line 1"):
        load_config(path)


# --- command-line options -----------------------------------------------------------------------------


@pytest.mark.parametrize("argv, match", [
    (["run", "--seed", str(2**64)], r"--seed: .*must be in \[0, 4294967295\]"),
    (["eval", "--model", "bandai", "--data", "x", "--k", "-3"], r"--k: .*must be in \[1, 2147483647\]"),
    (["eval", "--model", "bandai", "--data", "x", "--k", "0"], r"--k: .*must be in \[1, 2147483647\]"),
    (["predict", "--model", "bandai", "clip.bvh", "--out", "o", "--k", str(10**12)], r"--k: .*must be in \[1, 2147483647\]"),
])  # fmt: skip
def test_integer_options_are_range_checked(argv, match, capsys):
    from jaxmotion.cli import _parser

    with pytest.raises(SystemExit) as e:
        _parser().parse_args(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("usage:") and "Traceback" not in "".join(err), err  # argparse's usage, then the one error
    assert __import__("re").search(match, err[-1]), err[-1]


def test_test_files_on_the_synthetic_data_is_a_usage_error():
    from jaxmotion import experiment

    with pytest.raises(UsageError, match=r"--test-files applies to a plain folder of BVH clips; the synthetic dataset"):
        experiment.load_data(Config(), None, ["nomatch*"])


def test_an_unknown_marker_set_is_a_config_error_before_a_clip_is_read(tmp_path):
    from jaxmotion.cli import main

    (tmp_path / "clips").mkdir()
    (tmp_path / "clips" / "dataset-2_walk_normal_001.bvh").write_text("not read")
    cfg = tmp_path / "markers.py"
    cfg.write_text("from jaxmotion.config import Config\n\ndef get_config():\n"
                   "    return Config(name='m', method='mojo', data_options={'markers': 'nope'})\n")
    with pytest.raises(ConfigError, match=r"markers\.py: .*markers='nope': unknown marker set; known: \["):
        main(["train", "--config", str(cfg), "--data", str(tmp_path / "clips"), "--workdir", str(tmp_path / "run")])


def test_the_command_refuses_a_config_past_memory_in_one_line_before_training(tmp_path):
    cfg = tmp_path / "wide.py"
    cfg.write_text("from jaxmotion.config import Config\nfrom jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig\n\n"
                   "def get_config():\n    return Config(name='wide', method_config=DLowConfig(cvae=CVAEConfig(nh_rnn=10**6), q=QConfig()))\n")
    r = subprocess.run([sys.executable, "-m", "jaxmotion.cli", "run", "--config", str(cfg), "--workdir", str(tmp_path / "run")],
                       cwd=REPO, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "training (CVAEConfig): the widest layer's weights (1000000)" in lines[0] and "GiB at once" in lines[0], lines
    assert "data:" not in r.stdout and not (tmp_path / "run" / "cvae").exists()  # refused before any step


def test_orbax_thread_tracebacks_are_dropped_and_nothing_else(tmp_path):
    """A failed checkpoint write is the one `CheckpointError` line; orbax's threads' logged tracebacks are not shown."""
    import logging

    from jaxmotion.cli import _OrbaxThreadErrorsDropped

    def exc_info_from(filename: str):
        code = compile("def write():\n    raise ValueError('RESOURCE_EXHAUSTED: No space left on device')\n", filename, "exec")
        ns: dict = {}
        exec(code, ns)
        try:
            ns["write"]()
        except ValueError:
            return sys.exc_info()

    def record(exc_info) -> logging.LogRecord:
        return logging.LogRecord("absl", logging.ERROR, __file__, 1, "_SignalingThread.run() raised an exception", (), exc_info)

    orbax = exc_info_from("/venv/site-packages/orbax/checkpoint/_src/serialization/serialization.py")
    mine = exc_info_from(str(tmp_path / "my_module.py"))
    assert not _OrbaxThreadErrorsDropped.filter(record(orbax))
    assert _OrbaxThreadErrorsDropped.filter(record(mine)) and _OrbaxThreadErrorsDropped.filter(record(None))
    # A failed restore's leftover futures: tensorstore's error, raised in its threads, has no Python frame.
    store = ValueError("OUT_OF_RANGE: Error reading \"w/.zarray\" [tensorstore_spec='{\"driver\":\"zarr\"}']")
    other = ValueError("a frameless error of something else")
    assert not _OrbaxThreadErrorsDropped.filter(record((ValueError, store, None)))
    assert _OrbaxThreadErrorsDropped.filter(record((ValueError, other, None)))


def test_a_training_step_out_of_memory_is_a_config_error_not_a_checkpoint_error(tmp_path):
    from jaxmotion.train.loop import _raise_if_out_of_memory

    oom = RuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating 60963073504 bytes.")
    with pytest.raises(ConfigError, match=r"cvae: a training step ran out of memory \(RuntimeError: RESOURCE_EXHAUSTED.*lower the batch size"):
        _raise_if_out_of_memory(oom, tmp_path / "cvae")
    _raise_if_out_of_memory(OSError(28, "No space left on device"), tmp_path / "cvae")  # a full disk stays a checkpoint error


def test_a_full_disk_names_the_file_being_written(tmp_path, monkeypatch):
    from jaxmotion.formats.atomic import write_text_atomic

    from test_reliability_probes import _failing_writes_to

    target = tmp_path / "metrics.json"
    target.write_text("previous")
    _failing_writes_to(monkeypatch, "metrics")
    with pytest.raises(OSError, match=r"\[Errno 28\] No space left on device.*: '.*metrics\.json'") as e:
        write_text_atomic(target, "x" * 100)
    monkeypatch.undo()
    assert e.value.filename == str(target) and target.read_text() == "previous"


def test_the_python_api_refuses_a_config_past_memory_before_writing_anything(tmp_path):
    from jaxmotion import experiment
    from jaxmotion.data.synthetic import make_synthetic

    ds = make_synthetic(0, train_sequences=2, train_segments=4, test_sequences=1, test_segments=4)
    cfg = experiment.resolve(Config(eval_batch=10**9))
    with pytest.raises(ConfigError, match=r"config: evaluation: eval_batch 1000000000 x K 50 futures .* GiB at once"):
        experiment.train(cfg, experiment.prepare(ds, 8), tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_a_coroutine_left_unawaited_after_a_user_error_prints_nothing_more():
    """A failed restore can leave orbax's coroutines unawaited; the console script's error stays one line."""
    import subprocess

    code = ("import sys; import jaxmotion.cli as cli\n"
            "from jaxmotion.train.loop import CheckpointError\n"
            "async def read(): pass\n"
            "def main(argv=None):\n"
            "    global left\n"
            "    left = read()\n"
            "    raise CheckpointError('ckpt: checkpoint step 3 does not restore')\n"
            "cli.main = main\n"
            "sys.exit(cli.entry())\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2 and r.stderr.splitlines() == ["jaxmotion: error: ckpt: checkpoint step 3 does not restore"], r.stderr
