import os
import subprocess
import sys

import pytest

from jaxmotion.train import hugepages


def test_thp_mode_reads_the_bracketed_choice(tmp_path):
    f = tmp_path / "enabled"
    f.write_text("always [madvise] never\n")
    assert hugepages.thp_mode(f) == "madvise"
    f.write_text("[always] madvise never\n")
    assert hugepages.thp_mode(f) == "always"
    assert hugepages.thp_mode(tmp_path / "missing") is None


@pytest.mark.parametrize("mode", ["always", "never", None])
def test_no_restart_where_the_kernel_mode_makes_the_tunable_pointless(mode):
    assert not hugepages.wanted({}, mode=mode or "")


def test_no_restart_when_switched_off_or_already_set():
    assert not hugepages.wanted({hugepages.OFF_SWITCH: "0"}, mode="madvise")
    assert not hugepages.wanted({"GLIBC_TUNABLES": f"glibc.malloc.arena_max=2:{hugepages.TUNABLE}"}, mode="madvise")


def test_with_tunable_keeps_the_other_tunables():
    env = hugepages.with_tunable({"GLIBC_TUNABLES": "glibc.malloc.arena_max=2", "X": "1"})
    assert env == {"GLIBC_TUNABLES": f"glibc.malloc.arena_max=2:{hugepages.TUNABLE}", "X": "1"}
    assert hugepages.with_tunable({})["GLIBC_TUNABLES"] == hugepages.TUNABLE
    assert hugepages.with_tunable(env)["GLIBC_TUNABLES"] == env["GLIBC_TUNABLES"]  # not added twice
    assert hugepages.with_tunable(env, on=False) == {"GLIBC_TUNABLES": "glibc.malloc.arena_max=2", "X": "1"}
    assert "GLIBC_TUNABLES" not in hugepages.with_tunable({"GLIBC_TUNABLES": hugepages.TUNABLE}, on=False)


def _child_tunables(env: dict) -> str:
    code = ("import os, sys; from jaxmotion.train.hugepages import exec_with_hugepages; print('start', flush=True); "
            "exec_with_hugepages(); print(os.environ.get('GLIBC_TUNABLES', ''))")
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout


def test_the_restart_sets_the_tunable_once_where_it_is_wanted():
    env = {k: v for k, v in os.environ.items() if k not in ("GLIBC_TUNABLES", hugepages.OFF_SWITCH)}
    out = _child_tunables(env).split()
    if hugepages.wanted(env):
        assert out == ["start", "start", hugepages.TUNABLE]  # the program ran again from the start, once
    else:
        assert out == ["start"]
    assert _child_tunables({**env, hugepages.OFF_SWITCH: "0"}).split() == ["start"]
