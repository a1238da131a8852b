"""benchmarks/animation.py times this tree's futures GIF against a git revision's and compares the files."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def test_against_the_checked_out_revision_the_gifs_are_byte_identical(tmp_path, capsys):
    if subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode != 0:
        pytest.skip("not a git checkout: benchmarks/animation.py reads the baseline from git")
    from benchmarks import animation

    dirty = subprocess.run(["git", "-C", str(ROOT), "diff", "--quiet", "HEAD", "--", animation.MODULE]).returncode != 0
    out = tmp_path / "animation.json"
    assert animation.main(["--base", "HEAD", "--k", "3", "--rounds", "2", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    (row,) = doc["rows"]
    assert row["K"] == 3 and row["base_s"] > 0 and row["this_tree_s"] > 0 and "machine" in doc
    if not dirty:  # the same code on both sides draws the same file
        assert row["byte_identical"], row
    assert "K = 3:" in capsys.readouterr().out


def test_an_unknown_revision_is_one_clear_error(tmp_path):
    from benchmarks import animation

    with pytest.raises(SystemExit, match="cannot show"):
        animation.main(["--base", "no-such-revision", "--out", str(tmp_path / "a.json")])
