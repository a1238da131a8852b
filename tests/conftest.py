"""Fixtures shared by several test modules: one tiny trained DLow run per session (tests/test_cli.py, tests/test_viewer.py);
one persistent XLA compilation cache per test session, shared by the pytest workers and the processes tests start;
and XLA's cheapest backend optimisation level for the tests' tiny programs (on the 2-core Intel Xeon, 2026-12-02,
quiet: the suite took 649 s with neither, 606 s with the cache, 461 s with both)."""

import os
import shutil
import tempfile

import pytest

_CACHE_ENV = "JAXMOTION_TEST_COMPILATION_CACHE"


def pytest_configure(config):
    """Points jax's persistent compilation cache at one fresh folder for this test session.

    Most of a test's time on the 2-core CPU is compiling, and many tests compile the same programs
    again: a resumed run recompiles its training step, every end-to-end test compiles the same
    evaluation, subprocesses start cold. The first process (pytest itself, before its xdist workers
    start) makes the folder and puts it in the environment, so the workers and every subprocess a
    test starts inherit it; it is removed at the end. A folder set by the user
    (`JAX_COMPILATION_CACHE_DIR`) is used as it is. The cache changes no result: a hit loads the
    executable XLA compiled for the same program.
    """
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        os.environ[_CACHE_ENV] = os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxmotion-test-xla-")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
    # XLA's cheapest backend optimisation level: the tests' programs are tiny, so LLVM's optimisation
    # passes cost more than they save (measured: see the module docstring; tests/test_distributed.py
    # already used this level for its subprocesses). XLA's own graph optimisations still run; the
    # numbers a test checks do not depend on it. Set the flag yourself (any
    # `--xla_backend_optimization_level=N` in XLA_FLAGS) to test with another level.
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" not in flags:
        os.environ["XLA_FLAGS"] = (flags + " --xla_backend_optimization_level=0").strip()
    import jax

    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))


@pytest.hookimpl(optionalhook=True)  # pytest without pytest-xdist (or `-p no:xdist`) has no such hook
def pytest_xdist_auto_num_workers(config):
    """`-n auto`: one and a half workers a logical CPU (3 on 2 cores; `--maxprocesses` still caps it).

    A worker spends much of its time waiting: on a `jaxmotion` subprocess it started, on XLA's
    single-threaded compiler while the other core idles, on file writes. With one worker a CPU the
    2-core machine kept 1.64 cores busy over the suite (process CPU time over wall time); a third
    worker fills the gaps. `-n N` chooses any other count.
    """
    return max(1, (3 * (os.cpu_count() or 1)) // 2)


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput") and _CACHE_ENV in os.environ:  # the process that made it
        shutil.rmtree(os.environ.pop(_CACHE_ENV), ignore_errors=True)

# DLow on the synthetic data on a tiny budget: trains, evaluates and reports in seconds.
TINY = """
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig
def get_config():
    return Config(name="tiny", method_config=DLowConfig(
                      cvae=CVAEConfig(num_steps=30, batch_size=16, nz=16, nh_rnn=32, nh_mlp=(32,)),
                      q=QConfig(num_steps=10, batch_size=4, nh_mlp=(32,))),
                  eval_k=(6, 2), ckpt_every=10, log_every=10, max_test_windows=40, eval_batch=16)
"""


@pytest.fixture(scope="session")
def tiny_cli_run(tmp_path_factory):
    """Returns `(config file, work directory)` of `jaxmotion run` with the TINY config (trained once per session).

    Tests may add files to the work directory (or re-evaluate it) but must not remove or corrupt what the run wrote.
    """
    from jaxmotion.cli import main

    d = tmp_path_factory.mktemp("cli")
    cfg = d / "tiny.py"
    cfg.write_text(TINY)
    assert main(["run", "--config", str(cfg), "--workdir", str(d / "work")]) == 0
    return cfg, d / "work"


def kill_at_step(monkeypatch, step: int):
    """Makes a training run die during `step` (`TrainSampler.sample`'s call of that step raises KeyboardInterrupt, as
    a kill would stop it); returns the function that puts the sampler back."""
    from jaxmotion.data.windows import TrainSampler

    real, calls = TrainSampler.sample, {"n": 0}

    def dies(self, rng, batch_size):
        calls["n"] += 1
        if calls["n"] == step:
            raise KeyboardInterrupt("killed")
        return real(self, rng, batch_size)

    monkeypatch.setattr(TrainSampler, "sample", dies)
    return lambda: monkeypatch.setattr(TrainSampler, "sample", real)
