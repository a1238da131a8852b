"""Data parallelism: a run sharded over 4 devices, or over 2 processes, is the one-device run.

This file is also the worker the tests start (`python tests/test_distributed.py one|devices|process ...`):
the pytest process already has JAX with one CPU device, so 4 devices
(`--xla_force_host_platform_device_count=4`) and `jax.distributed` need processes of their own, and
the one-device reference runs in one too, beside the 4-device one (two cores), under the same XLA
flags. Every run draws the same global batches. Sharded float32 sums are reassociated (the gradient
all-reduce, BatchNorm's batch moments), hence a tolerance, not bitwise equality.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

TIMEOUT = 300
TOL = dict(rtol=1e-4, atol=1e-5)
KILL_AT = 4  # the two-process run kills itself when it draws the batch of this CVAE step (checkpoint 4 is written)


def _configs() -> dict:
    from jaxmotion.config import Config
    from jaxmotion.models.divsamp import DivSampConfig
    from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig

    common = dict(eval_k=(4,), ckpt_every=4, log_every=2, max_test_windows=8, eval_batch=8)
    dlow = DLowConfig(cvae=CVAEConfig(num_steps=6, batch_size=8, nz=8, nh_rnn=16, nh_mlp=(16,)),
                      q=QConfig(num_steps=2, batch_size=4, nh_rnn=16, nh_mlp=(16,)))
    divsamp = DivSampConfig(hidden=16, nz=8, cvae_residual=1, sampler_residual=0, num_bases=4, base_dim=8, nh=8,
                            cvae_num_steps=4, cvae_batch_size=8, num_steps=0, batch_size=4, nk=4)
    return {"dlow": Config(name="dist_dlow", method_config=dlow, **common),
            "divsamp": Config(name="dist_divsamp", method="divsamp", method_config=divsamp, **common)}


def _prepared(cfg):
    from jaxmotion import experiment

    cfg = experiment.resolve(cfg)
    return cfg, experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)


def _leaves(params) -> dict[str, np.ndarray]:
    import jax

    from jaxmotion.train import distributed

    return {jax.tree_util.keystr(p): distributed.gather(v) for p, v in jax.tree_util.tree_leaves_with_path(params)}


def _killed_at(method, stage: str, step: int):
    """Returns `method` whose `stage` SIGKILLs its process when asked for the batch of `step` (its checkpoint is written)."""
    def stages(cfg, prep):
        out = []
        for s in method.stages(cfg, prep):
            if s.name == stage:
                want = np.random.default_rng([s.data_seed, step]).bit_generator.state

                def batches(rng, inner=s.batches):
                    if rng.bit_generator.state == want:
                        os.kill(os.getpid(), signal.SIGKILL)
                    return inner(rng)

                s = dataclasses.replace(s, batches=batches)
            out.append(s)
        return out

    return dataclasses.replace(method, stages=stages)


def _worker_train(out: Path, devices: int) -> None:
    """Trains both methods (and evaluates DLow) on this process's `devices` devices; with 4, a batch of 6 is the clear error."""
    import jax

    from jaxmotion import experiment
    from jaxmotion.errors import ConfigError

    assert jax.device_count() == devices, jax.devices()
    for name, cfg in _configs().items():
        cfg, prep = _prepared(cfg)
        params = experiment.train(cfg, prep, out / name)
        np.savez(out / f"{name}.npz", **_leaves(params))
        if name == "dlow":
            experiment.evaluate(cfg, prep, params, out / name)
    if devices == 1:
        return
    cfg = _configs()["dlow"]
    cfg = dataclasses.replace(cfg, method_config=dataclasses.replace(
        cfg.method_config, cvae=dataclasses.replace(cfg.method_config.cvae, batch_size=6)))
    cfg, prep = _prepared(cfg)
    try:
        experiment.train(cfg, prep, out / "batch6")
    except ConfigError as e:
        (out / "batch6.txt").write_text(str(e))


def _worker_process(pid: int, port: int, work: Path, kill_at: int | None) -> None:
    """One of two processes training DLow; writes the parameters it ends with to `work/params<pid>.npz`.

    Process 0 writes `predictor.json` first, as `experiment.train` does, so the run loads with `jaxmotion.load`.
    """
    from jaxmotion.train import distributed

    distributed.initialize(f"127.0.0.1:{port}", 2, pid)
    from jaxmotion.methods import get_method
    from jaxmotion.tools.predictor import write_manifest
    from jaxmotion.train import runner

    cfg, prep = _prepared(_configs()["dlow"])
    if distributed.is_main():
        write_manifest(cfg, prep.dataset, work)
    method = get_method("dlow")
    if kill_at is not None:
        method = _killed_at(method, "cvae", kill_at)
    params = runner.train(method, cfg, prep, work, resume=kill_at is None)
    np.savez(work / f"params{pid}.npz", **_leaves(params))


def _env(cache: Path, devices: int = 1) -> dict:
    # Most of a tiny run is compiling: XLA's cheapest optimisation level, and launches of the same
    # programs share a persistent compilation cache.
    flags = f"--xla_backend_optimization_level=0 --xla_force_host_platform_device_count={devices}"
    return dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS=flags, JAX_COMPILATION_CACHE_DIR=str(cache),
                JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0", JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _assert_close(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b) and a
    for k in a:
        np.testing.assert_allclose(a[k], b[k], err_msg=k, **TOL)


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("jax_cache")


@pytest.fixture(scope="module")
def runs(tmp_path_factory, cache) -> dict[int, Path]:
    """`{devices: folder}` of the one-device and the 4-device runs (two processes at once)."""
    root = tmp_path_factory.mktemp("runs")
    out = {d: root / str(d) for d in (1, 4)}
    procs = {d: subprocess.Popen([sys.executable, __file__, "one" if d == 1 else "devices", str(o)], env=_env(cache, d),
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True) for d, o in out.items()}
    for d, p in procs.items():
        try:
            _, err = p.communicate(timeout=TIMEOUT)
        finally:
            p.kill()
        assert p.returncode == 0, f"{d} device(s): {err[-3000:]}"
    return out


# A bias that BatchNorm follows has a zero gradient in exact arithmetic (BatchNorm subtracts the batch
# mean): its float gradient is rounding noise, which Adam turns into steps of +-lr, so it and the
# running mean it shifts differ between any two summation orders, on one device too. The rest agree.
def _bn_free(leaves: dict, method: str) -> dict:
    if method != "divsamp":
        return leaves
    return {k: v for k, v in leaves.items() if not (k.endswith("['gc']['bias']") or k.endswith("['bn']['mean']"))}


@pytest.mark.parametrize("method", ["dlow", "divsamp"])  # a GRU method; a BatchNorm one (batch moments over 4 devices)
def test_four_devices_train_as_one(method, runs):
    sharded, one = (_bn_free(dict(np.load(runs[d] / f"{method}.npz")), method) for d in (4, 1))
    _assert_close(sharded, one)
    losses = lambda d: [r["loss"] for r in map(json.loads, (runs[d] / method / "cvae" / "log.jsonl").read_text().splitlines())]  # noqa: E731
    np.testing.assert_allclose(losses(4), losses(1), rtol=1e-5)


def test_sharded_evaluation_equals_unsharded(runs):
    got, want = (json.loads((runs[d] / "dlow" / "metrics.json").read_text()) for d in (4, 1))
    assert [(r["method"], r["K"]) for r in got] == [(r["method"], r["K"]) for r in want] and len(got) == 3
    for g, w in zip(got, want):
        assert g["n_windows"] == w["n_windows"] == 8
        assert sorted(g["metrics"]) == sorted(w["metrics"])
        for k, v in w["metrics"].items():
            assert g["metrics"][k] == pytest.approx(v, rel=1e-4, abs=1e-5), (g["method"], k)


def test_batch_that_does_not_split_over_the_devices_is_a_clear_error(runs):
    msg = (runs[4] / "batch6.txt").read_text()
    assert "stage 'cvae' of method 'dlow'" in msg and "batch size 6" in msg and "4 devices" in msg
    assert not (runs[4] / "batch6" / "cvae").exists()  # reported before any stage trained


def _two_processes(work: Path, kill_at: int | None, cache: Path) -> list[int]:
    port, env = _free_port(), _env(cache)
    cmd = lambda i: [sys.executable, __file__, "process", str(i), str(port), str(work)] + ([str(kill_at)] if kill_at else [])  # noqa: E731
    logs = [open(work.parent / f"{work.name}-{kill_at}-{i}.log", "w") for i in range(2)]
    procs = [subprocess.Popen(cmd(i), env=env, stdout=logs[i], stderr=subprocess.STDOUT) for i in range(2)]
    t0 = time.monotonic()
    try:
        while any(p.poll() is None for p in procs):
            late = time.monotonic() - t0 > TIMEOUT
            # A process left waiting on a killed peer is killed too (it would wait for JAX's heartbeat timeout).
            if late or (kill_at and any(p.returncode == -signal.SIGKILL for p in procs)):
                time.sleep(0 if late else 5)
                for p in procs:
                    if p.poll() is None:
                        p.kill()
            time.sleep(0.05)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()
        for f in logs:
            f.close()
    assert time.monotonic() - t0 < TIMEOUT, "the two processes did not finish in time"
    return [p.returncode for p in procs]


@pytest.fixture(scope="module")
def two(tmp_path_factory, cache) -> dict:
    """The two-process DLow run, killed at checkpoint `KILL_AT` and then resumed: its folder, what each launch left."""
    root = tmp_path_factory.mktemp("two")
    work = root / "two"
    killed = _two_processes(work, KILL_AT, cache)
    after_kill = sorted(int(p.name) for p in (work / "cvae" / "ckpt").iterdir() if p.name.isdigit())
    later_stage = (work / "dlow_k4").exists()
    resumed = _two_processes(work, None, cache)
    log = lambda kill_at, i: (root / f"two-{kill_at}-{i}.log").read_text()[-3000:]  # noqa: E731
    return dict(work=work, killed=killed, after_kill=after_kill, later_stage=later_stage, resumed=resumed, log=log)


def test_two_processes_on_localhost_train_as_one_and_resume(two, runs):
    work = two["work"]
    assert two["killed"][0] == -signal.SIGKILL, two["log"](KILL_AT, 0)
    steps = two["after_kill"]
    assert steps and max(steps) == KILL_AT and not two["later_stage"]
    log = lambda i: two["log"](None, i)  # noqa: E731
    assert two["resumed"] == [0, 0], log(0) + log(1)
    p0, p1 = dict(np.load(work / "params0.npz")), dict(np.load(work / "params1.npz"))
    assert sorted(p0) == sorted(p1)
    for k in p0:
        np.testing.assert_array_equal(p0[k], p1[k], err_msg=k)  # replicated: one value, not two close ones
    _assert_close(p0, dict(np.load(runs[1] / "dlow.npz")))
    # Only process 0 logs and shows progress bars; the resumed log holds each step once, as the one-process run's.
    assert "dlow cvae" in log(0) and "dlow cvae" not in log(1)
    steps = lambda d: [r["step"] for r in map(json.loads, (d / "cvae" / "log.jsonl").read_text().splitlines())]  # noqa: E731
    assert steps(work) == steps(runs[1] / "dlow") == [2, 4, 6]


def test_two_process_run_loads_and_predicts_in_one_process(two):
    """A run trained on two processes loads in this one (one device): orbax's checkpoint names both processes' devices."""
    import jax

    import jaxmotion
    from jaxmotion import experiment

    assert two["resumed"] == [0, 0], two["log"](None, 0)
    assert jax.process_count() == 1
    cfg, prep = _prepared(_configs()["dlow"])
    model = jaxmotion.load(two["work"])
    x, key = prep.x[:3], jax.random.key(5)
    got = model.predict(x, k=4, key=key, method="dlow")
    assert got.shape == (3, 4, prep.dataset.t_pred, prep.dataset.dim) and np.isfinite(got).all()
    # The parameters the two processes ended with, exactly; and those `experiment.restore` gives.
    np.testing.assert_equal(_leaves(model.params), dict(np.load(two["work"] / "params0.npz")))
    params = experiment.restore(cfg, prep, two["work"])
    assert sorted(params) == sorted(model.params) == ["cvae", "dlow_k4"]
    np.testing.assert_equal(_leaves(params), _leaves(model.params))
    want = experiment.predictors(cfg, prep.dataset, params, 4)["dlow"](jax.numpy.asarray(x), key)
    np.testing.assert_array_equal(got, np.asarray(want))


def test_initialize_without_settings_is_a_no_op_and_bad_settings_are_clear(monkeypatch):
    from jaxmotion.train import distributed
    from jaxmotion.errors import ConfigError

    for v in distributed.ENV.values():
        monkeypatch.delenv(v, raising=False)
    assert distributed.initialize() is False
    with pytest.raises(ConfigError, match=r"process_id must be in \[0, num_processes = 2\), got 2"):
        distributed.initialize("127.0.0.1:1234", 2, 2)
    monkeypatch.setenv("JAX_NUM_PROCESSES", "two")
    with pytest.raises(ConfigError, match="JAX_NUM_PROCESSES='two'"):
        distributed.initialize()


if __name__ == "__main__":
    mode, *rest = sys.argv[1:]
    if mode in ("one", "devices"):
        _worker_train(Path(rest[0]), 1 if mode == "one" else 4)
    else:
        _worker_process(int(rest[0]), int(rest[1]), Path(rest[2]), int(rest[3]) if len(rest) > 3 else None)
