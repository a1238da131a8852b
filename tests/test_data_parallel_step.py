"""The data-parallel train step: one gradient all-reduce per step, outside every loop; every method's
stages step on 4 devices as on one (DLow's stages and DivSamp's CVAE over whole runs in
tests/test_distributed.py); micro-batches (gradient accumulation) step as the whole batch.

The tests run in worker processes of their own (`python tests/test_data_parallel_step.py
collectives|steps OUT`) with 4
forced CPU host devices (`--xla_force_host_platform_device_count=4`); the pytest process has JAX with
one. The one-device reference is the same step on a mesh of the first device only, so both run in
the worker under the same XLA flags.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TIMEOUT = 900
DEVICES = 4
# Stages whose 4-device training tests/test_distributed.py checks against one device over whole runs, not
# compiled again here: DivSamp's CVAE, and both of DLow's (so DLow is not among the configs below; its CVAE in
# micro-batches: the last test below).
COVERED = ("divsamp/cvae",)


def _configs() -> dict:
    from jaxmotion.config import Config
    from jaxmotion.models.divsamp import DivSampConfig
    from jaxmotion.models.gsps import GSPSConfig
    from jaxmotion.models.mojo import MojoConfig
    from jaxmotion.models.motionmap import MotionMapConfig

    common = dict(eval_k=(4,), action_metrics=False, max_test_windows=8)
    return {
        "mojo": Config(method="mojo", method_config=MojoConfig(nz=4, nh_rnn=16, nh_mlp=(16,), q_nh_rnn=8, q_nh_mlp=(16,), num_steps=2,
                                                              batch_size=8, q_num_steps=2, q_batch_size=8), **common),
        "divsamp": Config(method="divsamp", method_config=DivSampConfig(
            hidden=16, nz=8, cvae_residual=1, sampler_residual=0, num_bases=4, base_dim=8, nh=8, cvae_num_steps=2, cvae_batch_size=8,
            num_steps=2, batch_size=8, nk=4), **common),
        "gsps": Config(method="gsps", method_config=GSPSConfig(
            prior_batch_size=32, prior_num_steps=2, hidden=8, num_stage=1, nz=4, n_pre=5, nk1=2, nk2=2, batch_size=8, num_steps=2,
            mm_candidate_stride=60), **common),
        "motionmap": Config(method="motionmap", method_config=MotionMapConfig(
            nh_rnn=16, nh_fuse=16, nh_uncertainty=16, n_uncertainty_layers=2, hm_size=16, ae_steps=2, hm_steps=2, ft_steps=2,
            batch_size=8, tsne_fit_points=200), **common),
    }


def _gathered(tree) -> dict[str, np.ndarray]:
    import jax

    return {jax.tree_util.keystr(p): np.asarray(v) for p, v in jax.tree_util.tree_leaves_with_path(tree)}


def _collectives(hlo: str) -> dict:
    """Returns `{"total": n, "in_loops": n}`: the collective ops of an optimised HLO module, and those in a while body."""
    ops = ("all-reduce", "all-gather", "reduce-scatter", "all-to-all", "collective-permute")
    pattern = re.compile(r"=\s*\S.*?\s(" + "|".join(ops) + r")(-start)?\(")
    bodies = set(re.findall(r"while\(.*?body=%?([\w.\-]+)", hlo))
    # Computations called from a while body (fusions, nested calls) are inside the loop too.
    comps, name = {}, None
    for line in hlo.splitlines():
        head = re.match(r"^\s*(?:ENTRY\s+)?%?([\w.\-]+)\s.*\{\s*$", line)
        if head and not line.startswith(" " * 4):
            name = head.group(1)
            comps[name] = []
        elif name is not None:
            comps[name].append(line)
    inner, todo = set(), list(bodies)
    while todo:
        c = todo.pop()
        if c in inner or c not in comps:
            continue
        inner.add(c)
        for line in comps[c]:
            todo += re.findall(r"(?:calls|body|condition|to_apply|branch_computations)=\{?%?([\w.\-]+)", line)
    count = lambda names: sum(1 for c in names for line in comps[c] if pattern.search(line))  # noqa: E731
    return {"total": count(comps), "in_loops": count(inner)}


def cvae_step_hlo(t_pred: int, mesh, t_his: int = 15, dim: int = 48, batch: int = 8) -> str:
    """Returns the optimised HLO of DLow's CVAE train step (tiny sizes) on `mesh`, for futures of `t_pred` frames."""
    import jax
    import jax.numpy as jnp
    import optax

    from jaxmotion.models import dlow
    from jaxmotion.train.loop import create_state, make_train_step

    cvae = dlow.cvae_model(dlow.CVAEConfig(nz=8, nh_rnn=16, nh_mlp=(16,)), dim, t_pred)
    params = cvae.init(jax.random.key(0), jnp.zeros((1, t_his, dim)), jnp.zeros((1, t_pred, dim)), jax.random.key(0))
    tx = optax.adam(1e-3)
    loss = lambda p, _f, b, k: dlow.cvae_loss(cvae, p, b, k, t_his=t_his, beta=0.1, lambda_v=1000.0)  # noqa: E731
    fn = jax.jit(make_train_step(loss, tx, mesh=mesh))
    windows = jax.ShapeDtypeStruct((batch, t_his + t_pred, dim), jnp.float32)
    return fn.lower(create_state(params, tx), windows, jax.random.key(0)).compile().as_text()


def _worker_collectives(out: Path) -> None:
    """Writes the collective counts of DLow's CVAE step (GRU encoders and decoder) on 2 devices, for two future lengths."""
    import jax
    from jax.sharding import Mesh

    two = Mesh(np.array(jax.devices()[:2]), ("data",))
    counts = {}
    for t_pred in (30, 60):
        hlo = cvae_step_hlo(t_pred, two)
        counts[str(t_pred)] = _collectives(hlo)
        (out / f"hlo_{t_pred}.txt").write_text(hlo)
    (out / "collectives.json").write_text(json.dumps(counts))


def _worker_steps(out: Path) -> None:
    import jax
    import optax
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    from jaxmotion import experiment
    from jaxmotion.train import distributed
    from jaxmotion.train import runner
    from jaxmotion.train.loop import bn_optimizer, create_state, make_bn_train_step, make_train_step

    assert jax.device_count() == DEVICES, jax.devices()
    meshes = {1: Mesh(np.array(jax.devices()[:1]), ("data",)), DEVICES: Mesh(np.array(jax.devices()), ("data",))}
    result: dict = {"steps": {}, "micro": {}}

    def step(stage, state, batch, key, devices, micro_batches=1):
        """Returns `(params before - after, metrics)` of one step by SGD with learning rate 1: minus the gradient.

        Not the stage's Adam, whose first step is about lr * sign(g): it would blow a gradient that is zero
        but for rounding (a bias BatchNorm follows) up to +-lr whichever way the rounding went.
        """
        tx = bn_optimizer(optax.sgd(1.0)) if stage.batch_norm else optax.sgd(1.0)
        make = make_bn_train_step if stage.batch_norm else make_train_step
        mesh = meshes[devices]
        fn = jax.jit(make(stage.loss, tx, mesh=mesh, micro_batches=micro_batches))
        state = distributed.replicate(create_state(state.params, tx, state.frozen), NamedSharding(mesh, PartitionSpec()))
        before = _gathered(state.params)
        batch = distributed.global_batch(batch, NamedSharding(mesh, PartitionSpec("data")))
        new, metrics = fn(state, batch, key)
        after = _gathered(new.params)
        return {k: before[k] - after[k] for k in before}, {k: float(v) for k, v in metrics.items()}

    for name, cfg in _configs().items():
        cfg = experiment.resolve(cfg)
        prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
        trained = {}
        for stage in experiment.get_method(cfg.method).stages(cfg, prep):
            state = runner.init_state(stage, trained)
            trained[stage.name] = state.params
            if stage.num_steps == 0 or f"{name}/{stage.name}" in COVERED:
                continue
            batch = stage.batches(np.random.default_rng([stage.data_seed, 0]))
            key = jax.random.key(7)
            one, m_one = step(stage, state, batch, key, 1)
            four, m_four = step(stage, state, batch, key, DEVICES)
            np.savez(out / f"{name}-{stage.name}-1.npz", **one)
            np.savez(out / f"{name}-{stage.name}-{DEVICES}.npz", **four)
            result["steps"][f"{name}/{stage.name}"] = {"bn": stage.batch_norm, "one": m_one, "four": m_four}
            if not stage.batch_norm:  # BatchNorm normalises each micro-batch by its own moments
                micro, m_micro = step(stage, state, batch, key, DEVICES, micro_batches=2)
                np.savez(out / f"{name}-{stage.name}-micro.npz", **micro)
                result["micro"][f"{name}/{stage.name}"] = {"one": m_one, "micro": m_micro}

    (out / "result.json").write_text(json.dumps(result, indent=1))


def _run(mode: str, out: Path, cache: Path | None = None) -> None:
    # Keeps the flags the test session set (tests/conftest.py: XLA's cheapest backend optimisation level).
    from jaxmotion.train.host_devices import host_device_env

    env = dict(host_device_env(os.environ, DEVICES), JAX_PLATFORMS="cpu")
    if cache is not None:  # most of the steps' worker is compiling; launches share a persistent cache
        env.update(JAX_COMPILATION_CACHE_DIR=str(cache), JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    p = subprocess.run([sys.executable, __file__, mode, str(out)], env=env, capture_output=True, text=True, timeout=TIMEOUT)
    assert p.returncode == 0, p.stderr[-4000:]


@pytest.fixture(scope="module")
def worker(tmp_path_factory) -> tuple[Path, dict]:
    """The steps of every method's stages on 1 and 4 devices, and with micro-batches (their parameters in `.npz` files)."""
    out = tmp_path_factory.mktemp("dp_step")
    _run("steps", out, tmp_path_factory.mktemp("jax_cache"))
    return out, json.loads((out / "result.json").read_text())


def test_one_gradient_all_reduce_per_step_outside_every_loop(tmp_path):
    """DLow's CVAE (GRU encoder and decoder scans) on 2 devices: the collectives do not grow with t_pred, none is in a loop."""
    _run("collectives", tmp_path)
    counts = json.loads((tmp_path / "collectives.json").read_text())
    assert counts["30"] == counts["60"], counts
    assert counts["30"]["in_loops"] == 0, counts
    assert 1 <= counts["30"]["total"] <= 4, counts  # the pmean of the gradients and metrics (XLA may split it by type)


def _assert_steps_equal(got: dict, want: dict, what: str) -> None:
    """Asserts two steps' updates (minus the gradients, the BatchNorm statistics' moves) agree to float32 sums' order.

    Measured over the whole tree, `|got - want| / |want|`: a bias that BatchNorm follows has a zero
    gradient in exact arithmetic, so its float gradient is rounding noise in any summation order, and
    BatchNorm over a few rows amplifies the rounding of the moments (DivSamp's sampler: 8e-5 here).
    Rows drawn or reduced wrongly are errors of percents.
    """
    assert sorted(got) == sorted(want) and want
    norm = lambda t: np.sqrt(sum(float(np.sum(np.square(v, dtype=np.float64))) for v in t))  # noqa: E731
    size = norm(want.values())
    assert size > 0, what
    err = norm(got[k] - want[k] for k in want) / size
    assert err < 2e-4, (what, err)


def _assert_metrics_equal(got: dict, want: dict, what: str) -> None:
    """Asserts equal metrics: the loss to 1e-4, the others to 1e-3 (MOJO's untrained diversity term, exp(-d2 / s) of large
    distances, turns their rounding into 2e-4)."""
    assert sorted(got) == sorted(want), what
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-4 if k == "loss" else 1e-3, abs=1e-6), (what, k, got[k], v)


@pytest.mark.slow  # compiles 22 train steps of 8 stages (2-6 minutes of CPU)
def test_every_method_and_stage_steps_on_four_devices_as_on_one(worker):
    out, result = worker
    steps = result["steps"]
    # Every trained stage of every method but DLow's and COVERED (computed stages, e.g. MotionMap's codebook, train nothing).
    assert sorted(steps) == sorted([
        "mojo/cvae", "mojo/q_k4", "divsamp/sampler", "gsps/prior", "gsps/generator",
        "motionmap/autoencoder", "motionmap/heatmap", "motionmap/finetune",
    ])
    for name, m in steps.items():
        one, four = (dict(np.load(out / f"{name.replace('/', '-')}-{d}.npz")) for d in (1, DEVICES))
        _assert_steps_equal(four, one, name)
        _assert_metrics_equal(m["four"], m["one"], name)


@pytest.mark.slow  # the same worker
def test_micro_batches_step_as_the_whole_batch(worker):
    out, result = worker
    micro = result["micro"]
    # MOJO's Q step is DLow's K-sample Q loss on MOJO's decoder; DLow's CVAE: the last test below.
    assert sorted(micro) == sorted(["mojo/cvae", "mojo/q_k4", "gsps/prior", "motionmap/autoencoder", "motionmap/heatmap",
                                    "motionmap/finetune"])
    for name, m in micro.items():  # 2 micro-batches on each of 4 devices against the whole batch on one
        one, acc = (dict(np.load(out / f"{name.replace('/', '-')}-{got}.npz")) for got in ("1", "micro"))
        _assert_steps_equal(acc, one, name)
        _assert_metrics_equal(m["micro"], m["one"], name)


def test_micro_batches_of_a_gru_step_on_one_device_and_a_batch_that_does_not_split():
    """In this process (one device): DLow's CVAE in 4 micro-batches steps as the whole batch; a batch of 6 is a clear error."""
    import jax
    import jax.numpy as jnp
    import optax

    from jaxmotion.train import distributed
    from jaxmotion.errors import ConfigError
    from jaxmotion.models import dlow
    from jaxmotion.train.loop import create_state, make_train_step

    t_his, t_pred, dim = 10, 20, 48
    cvae = dlow.cvae_model(dlow.CVAEConfig(nz=8, nh_rnn=16, nh_mlp=(16,)), dim, t_pred)
    params = cvae.init(jax.random.key(0), jnp.zeros((1, t_his, dim)), jnp.zeros((1, t_pred, dim)), jax.random.key(0))
    loss = lambda p, _f, b, k: dlow.cvae_loss(cvae, p, b, k, t_his=t_his, beta=0.1, lambda_v=1000.0)  # noqa: E731
    tx = optax.sgd(1.0)
    batch = jax.random.normal(jax.random.key(1), (8, t_his + t_pred, dim))
    steps = {m: jax.jit(make_train_step(loss, tx, micro_batches=m))(create_state(params, tx), batch, jax.random.key(2)) for m in (1, 4)}
    before = _gathered(params)
    (whole, m1), (acc, m4) = ((_gathered(s.params), m) for s, m in (steps[1], steps[4]))
    _assert_steps_equal({k: before[k] - acc[k] for k in before}, {k: before[k] - whole[k] for k in before}, "micro-batches")
    _assert_metrics_equal({k: float(v) for k, v in m4.items()}, {k: float(v) for k, v in m1.items()}, "micro-batches")
    with pytest.raises(ConfigError, match=r"batch size 6 does not split over 1 devices x 4 micro-batches.*multiple of 4"):
        distributed.check_batch(np.zeros((6, 3)), distributed.data_mesh(), "stage 'cvae'", micro_batches=4)


if __name__ == "__main__":
    {"collectives": _worker_collectives, "steps": _worker_steps}[sys.argv[1]](Path(sys.argv[2]))
