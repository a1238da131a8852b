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
    data = {s: {"Walking": np.full((4, 32, 3), 0.5, np.float64), 7: np.ones((3, 32, 3), np.int16)}
            for s in ("S1", "S5", "S6", "S7", "S8", "S9", "S11")}
    path = tmp_path / "h.npz"
    np.savez_compressed(path, positions_3d=np.array(data, dtype=object))
    ds = load_dataset(path)
    assert ds.name == "h36m" and len(ds.train) == 10 and float(ds.train[1].positions[0, 0, 0]) == 0.5


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


def _flip_64_bytes(step_dir: Path) -> None:
    """XORs 1 into 64 bytes in the middle of the checkpoint's largest file (array data): orbax restores it without error."""
    f = max((p for p in step_dir.rglob("*") if p.is_file()), key=lambda p: p.stat().st_size)
    data = bytearray(f.read_bytes())
    i = len(data) // 2
    data[i : i + 64] = bytes(b ^ 1 for b in data[i : i + 64])
    f.write_bytes(bytes(data))


# Flipped bits in a float's mantissa change it; in its exponent they may make it NaN or inf.
_CORRUPT = "its arrays restore to other bytes than were saved|it restores non-finite values"


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
    from jaxmotion.predict_file import predict_file

    _, work = tiny_cli_run
    model = jaxmotion.load(work)
    model.params = jax.tree.map(lambda a: a * np.nan, model.params)  # as a checkpoint without a checksum could restore
    with pytest.raises(CheckpointError, match=r"futures of this input hold NaN or inf .*nothing was written"):
        predict_file(model, _clip(work, tmp_path / "clip.npz"), tmp_path / "out", k=2)
    assert not (tmp_path / "out" / "futures.npz").exists()
