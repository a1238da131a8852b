"""Killed runs resume exactly: `jaxmotion train` as a subprocess, SIGKILLed, then `--resume`.

A run is killed, then resumed (and killed again, then resumed), at moments picked by watching its work
directory: after a random checkpoint of the first stage, during a checkpoint write (an orbax temporary
folder exists), or between the two stages (the first stage's last checkpoint is written, the second
stage has none). The final parameters (BatchNorm statistics included) must equal
an uninterrupted run's bitwise, and its `log.jsonl` files hold the same steps with the same metrics:
on one CPU the resumed run replays the same batches, keys and XLA programs from the same float32
state, so nothing may differ. A GRU method (DLow) and a BatchNorm method (DivSamp); each is four
`jaxmotion train` processes or fewer, sharing a compilation cache: slow.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion import experiment
from jaxmotion.config import load_config

pytestmark = pytest.mark.slow

CONFIGS = {
    "dlow": """
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig
def get_config():
    return Config(name="kill_dlow", action_metrics=False, method_config=DLowConfig(
                      cvae=CVAEConfig(num_steps=100, batch_size=8, nz=8, nh_rnn=16, nh_mlp=(16,)),
                      q=QConfig(num_steps=40, batch_size=4, nh_rnn=16, nh_mlp=(16,))),
                  eval_k=(4,), ckpt_every=20, log_every=10, max_test_windows=8, eval_batch=8)
""",
    "divsamp": """
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig
def get_config():
    return Config(name="kill_divsamp", action_metrics=False, method="divsamp", eval_k=(4,), ckpt_every=20, log_every=10, max_test_windows=8,
                  eval_batch=8, method_config=DivSampConfig(hidden=16, nz=8, cvae_residual=1, sampler_residual=0,
                  num_bases=4, base_dim=8, nh=8, cvae_num_steps=100, cvae_batch_size=8, num_steps=40, batch_size=4, nk=4))
""",
}
FIRST = "cvae"  # both methods' first stage; the second is dlow_k4 / sampler
TIMEOUT = 240


def _cmd(cfg: Path, work: Path, resume: bool = False) -> list[str]:
    return [sys.executable, "-m", "jaxmotion.cli", "train", "--config", str(cfg), "--workdir", str(work)] + (["--resume"] if resume else [])


def _env(cache: Path) -> dict:
    # The runs share a persistent compilation cache: the reference run compiles, the others load the same
    # executables (most of a tiny run's time is compilation).
    return dict(os.environ, JAX_PLATFORMS="cpu", PYTHONWARNINGS="default", JAX_COMPILATION_CACHE_DIR=str(cache),
                JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0", JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")


def _train(cfg: Path, work: Path, resume: bool = False) -> subprocess.CompletedProcess:
    p = subprocess.run(_cmd(cfg, work, resume), env=_env(cfg.parent / "jax_cache"), capture_output=True, text=True, timeout=TIMEOUT)
    assert p.returncode == 0, p.stderr[-3000:]
    return p


def _steps(ckpt: Path) -> list[int]:
    return sorted(int(p.name) for p in ckpt.iterdir() if p.name.isdigit()) if ckpt.is_dir() else []


def _kill_when(cfg: Path, work: Path, ready, what: str, resume: bool) -> None:
    """Starts a run and SIGKILLs it as soon as `ready(work)` holds (polled every millisecond)."""
    err = work.with_name(work.name + ".stderr")
    with open(err, "w") as stderr:
        proc = subprocess.Popen(_cmd(cfg, work, resume), env=_env(cfg.parent / "jax_cache"), stdout=subprocess.DEVNULL, stderr=stderr)
        t0 = time.monotonic()
        try:
            while not ready(work):
                if proc.poll() is not None:
                    pytest.fail(f"the run ended before {what}: {err.read_text()[-2000:]}")
                if time.monotonic() - t0 > TIMEOUT:
                    pytest.fail(f"no {what} within {TIMEOUT} s")
                time.sleep(0.001)
            proc.send_signal(signal.SIGKILL)
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL


def _params(cfg: Path, work: Path) -> dict:
    cfg = experiment.resolve(load_config(cfg))
    prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
    return experiment.restore(cfg, prep, work)


def _logs(work: Path) -> dict[str, list[dict]]:
    out = {}
    for log in sorted(work.glob("*/log.jsonl")):
        rows = [json.loads(line) for line in log.read_text().splitlines()]
        out[log.parent.name] = [{k: v for k, v in r.items() if k != "time_s"} for r in rows]
    return out


def _after_checkpoint(work: Path, first_steps: int) -> tuple:
    step = random.Random(os.getpid()).choice(range(20, first_steps, 20))
    return lambda w: step in _steps(w / FIRST / "ckpt"), f"checkpoint {step} of {FIRST!r}"


def _during_write(work: Path, first_steps: int) -> tuple:
    def writing(w: Path) -> bool:
        ckpt = w / FIRST / "ckpt"
        return ckpt.is_dir() and bool(_steps(ckpt)) and any(".orbax-checkpoint-tmp" in p.name for p in ckpt.iterdir())

    return writing, f"a checkpoint write of {FIRST!r} after its first checkpoint"


def _between_stages(work: Path, first_steps: int) -> tuple:
    return lambda w: first_steps in _steps(w / FIRST / "ckpt"), f"the last checkpoint {first_steps} of {FIRST!r}"


# DivSamp is killed mid-stage, where its BatchNorm statistics and optimiser state must come back; DLow
# during a write and between its stages. Each kill is resumed, and the last resumed run finishes.
KILLS = {"dlow": (_during_write, _between_stages), "divsamp": (_after_checkpoint,)}


@pytest.mark.parametrize("method", sorted(CONFIGS))
def test_killed_run_resumes_to_the_uninterrupted_run(method, tmp_path):
    cfg = tmp_path / f"{method}.py"
    cfg.write_text(CONFIGS[method])
    ref, work = tmp_path / "ref", tmp_path / "killed"
    _train(cfg, ref)
    first_steps = _steps(ref / FIRST / "ckpt")[-1]
    second = next(p.name for p in ref.iterdir() if p.is_dir() and p.name != FIRST)
    for n, kill in enumerate(KILLS[method]):
        ready, what = kill(work, first_steps)
        _kill_when(cfg, work, ready, what, resume=n > 0)
        left = sorted(p.name for p in (work / FIRST / "ckpt").iterdir())
        print(f"{method}: killed at {what}; {FIRST}/ckpt holds {left}")
        if kill is _between_stages:
            assert _steps(work / second / "ckpt") == [], "the kill came after the second stage's first checkpoint"
        else:
            assert max(_steps(work / FIRST / "ckpt")) < first_steps  # inside the first stage
    _train(cfg, work, resume=True)

    a, b = _params(cfg, work), _params(cfg, ref)
    la, lb = jax.tree_util.tree_leaves_with_path(a), jax.tree_util.tree_leaves_with_path(b)
    assert [p for p, _ in la] == [p for p, _ in lb] and len(la) > 0
    for (path, x), (_, y) in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=jax.tree_util.keystr(path))
    logs = _logs(work)
    assert sorted(logs) == sorted([FIRST, second]) and all(logs.values())
    assert logs == _logs(ref)
