"""Cache writes are whole or not at all (`jaxmotion.formats.atomic`): what several processes rely on."""

import os

import numpy as np
import pytest

from jaxmotion.formats import atomic
from jaxmotion.formats.atomic import savez_atomic, write_text_atomic


def test_savez_keeps_the_name_and_leaves_no_temporary_file(tmp_path):
    path = savez_atomic(tmp_path / "deep" / "sets.npz", idx=np.arange(3), mask=np.ones(3, bool))
    assert path == tmp_path / "deep" / "sets.npz" and sorted(os.listdir(path.parent)) == ["sets.npz"]
    with np.load(path) as z:
        np.testing.assert_array_equal(z["idx"], np.arange(3))
    # Written twice (two processes computing the same cache): the second replaces the first.
    savez_atomic(path, idx=np.arange(5), mask=np.ones(5, bool))
    with np.load(path) as z:
        assert z["idx"].shape == (5,)


def test_a_write_that_fails_midway_keeps_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    path = write_text_atomic(tmp_path / "manifest.json", "old")

    def broken_savez(f, **arrays):
        f.write(b"half a file")
        raise OSError("disk full")

    monkeypatch.setattr(atomic.np, "savez", broken_savez)
    with pytest.raises(OSError, match="disk full"):
        savez_atomic(path, x=np.zeros(2))
    assert path.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["manifest.json"]
