"""What a demanding user's probes found, each pinned: no code runs from a data file, no result is lost,
every user error is one named message (the subprocess tests check stderr for tracebacks)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.data.datasets import load_dataset, load_h36m
from jaxmotion.errors import DataError

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
