"""`--host-devices N`: a run's steps split over N CPU host devices of one process, its errors one line each."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import jax
import numpy as np
import pytest

from jaxmotion.cli import main
from jaxmotion.errors import UsageError
from jaxmotion.train.host_devices import HOST_DEVICES_FLAG

from conftest import kill_at_step
from test_cli import _params


def test_a_bad_count_or_a_clash_with_xla_flags_is_a_clear_error(tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit):
        main(["train", "--host-devices", "0"])
    assert "--host-devices: must be in [1, 256], got 0" in capsys.readouterr().err
    monkeypatch.setenv("XLA_FLAGS", f"{HOST_DEVICES_FLAG}=4")
    with pytest.raises(UsageError, match=f"--host-devices 2: XLA_FLAGS already sets {HOST_DEVICES_FLAG}=4"):
        main(["train", "--host-devices", "2"])


def test_a_backend_started_with_other_devices_is_a_clear_error(monkeypatch):
    # This process's CPU backend has started (one device, with the test session's flags): the flag can no longer take effect.
    assert len(jax.local_devices()) == 1
    monkeypatch.setenv("XLA_FLAGS", "")
    with pytest.raises(UsageError, match="had already started with 1 device"):
        main(["train", "--host-devices", "2"])
    assert os.environ["XLA_FLAGS"] == f"{HOST_DEVICES_FLAG}=2"  # set for a process that has not started jax


TINY = """
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig
def get_config():
    return Config(name="tiny_host", action_metrics=False, method_config=DLowConfig(
                      cvae=CVAEConfig(num_steps=20, batch_size=8, nz=8, nh_rnn=16, nh_mlp=(16,)),
                      q=QConfig(num_steps=4, batch_size=4, nh_rnn=16, nh_mlp=(16,))),
                  eval_k=(2,), ckpt_every=10, log_every=5, max_test_windows=8, eval_batch=8)
"""


@pytest.mark.slow
def test_a_one_device_checkpoint_resumes_on_two_host_devices(tmp_path, monkeypatch):
    """A run killed at CVAE step 13 on one device (checkpoint 10) finishes on two host devices (the command checks
    that it has them), every step once (that N devices train as one: tests/test_data_parallel_step.py)."""
    cfg, work = tmp_path / "tiny.py", tmp_path / "run"
    cfg.write_text(TINY)
    restore = kill_at_step(monkeypatch, 13)
    with pytest.raises(KeyboardInterrupt):
        main(["train", "--config", str(cfg), "--workdir", str(work)])
    restore()
    assert max(int(p.name) for p in (work / "cvae" / "ckpt").iterdir() if p.name.isdigit()) == 10
    # The test session's XLA flags (tests/conftest.py) without any host device count of their own.
    env = dict(os.environ, XLA_FLAGS=re.sub(HOST_DEVICES_FLAG + r"=\d+", "", os.environ.get("XLA_FLAGS", "")).strip())
    p = subprocess.run([sys.executable, "-m", "jaxmotion.cli", "train", "--config", str(cfg), "--workdir", str(work),
                        "--resume", "--host-devices", "2"], env=dict(env, JAX_PLATFORMS="cpu"), capture_output=True, text=True,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    steps = [json.loads(line)["step"] for line in (work / "cvae" / "log.jsonl").read_text().splitlines()]
    assert steps == [5, 10, 15, 20]
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(_params(cfg, work)))
