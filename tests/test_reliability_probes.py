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
