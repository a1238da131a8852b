"""benchmarks/flag_ab.py: setting B (or A's checkout) must be given, `--env` must be NAME=VALUE, `--base-tree` a checkout (checked before any worker runs)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks import flag_ab  # noqa: E402


def test_flag_ab_without_a_setting_b_is_refused(capsys):
    with pytest.raises(SystemExit):
        flag_ab.main(["--pairs", "1"])
    assert "--flag and/or --env" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["GLIBC_TUNABLES", "=x"])
def test_flag_ab_env_must_be_name_equals_value(bad, capsys):
    with pytest.raises(SystemExit):
        flag_ab.main(["--env", bad])
    assert "NAME=VALUE" in capsys.readouterr().err


def test_flag_ab_base_tree_must_be_a_checkout(tmp_path, capsys):
    with pytest.raises(SystemExit):
        flag_ab.main(["--base-tree", str(tmp_path), "--pairs", "1"])
    assert "no benchmarks/flag_ab.py there" in capsys.readouterr().err
