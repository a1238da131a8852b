"""A method from outside jaxmotion: registered by a config file, trained, resumed and evaluated with no jaxmotion edit."""

import json
import shutil

import numpy as np
import optax
import pytest

from jaxmotion import experiment
from jaxmotion.cli import main
from jaxmotion.config import Config, load_config
from jaxmotion.method import Method, Stage, register
from jaxmotion.train.runner import CheckpointMismatch
from jaxmotion.eval import evaluate_windows

# A whole method in one config file: a learned constant velocity plus a learned spread of K samples.
TOY = '''
import dataclasses
import jax, jax.numpy as jnp, optax
from jaxmotion.config import Config
from jaxmotion.method import Method, Stage, register
from jaxmotion.methods.common import window_batches


@dataclasses.dataclass
class ToyConfig:
    num_steps: int = 40
    lr: float = 0.05


def stages(cfg, prep):
    ds, c = prep.dataset, cfg.method_config
    t = jnp.arange(1, ds.t_pred + 1, dtype=jnp.float32)[:, None]

    def loss(p, frozen, batch, key):
        x, y = batch[:, : ds.t_his], batch[:, ds.t_his :]
        err = jnp.mean((x[:, -1:] + t * p["v"] - y) ** 2)
        return err, {"mse": err}

    velocity = Stage(name="velocity", init=lambda key, _frozen: {"v": jnp.zeros(ds.dim)}, optimizer=optax.adam(c.lr),
                     loss=loss, batches=window_batches(prep, 16), num_steps=c.num_steps, init_seed=cfg.seed, data_seed=cfg.seed)
    # A stage that trains nothing: its parameters are computed from the frozen velocity stage.
    spread = Stage(name="spread", init=lambda key, frozen: {"s": jnp.abs(frozen["velocity"]["v"]).mean() + 0.01},
                   optimizer=optax.set_to_zero(), loss=None, batches=None, num_steps=0, frozen=("velocity",))
    return [velocity, spread]


def predictors(cfg, ds, params, k):
    t = jnp.arange(1, ds.t_pred + 1, dtype=jnp.float32)[:, None]
    v = params["velocity"]["v"]

    def sample(x, key):
        mean = x[:, None, -1:] + t * v
        return mean + params["spread"]["s"] * jax.random.normal(key, (x.shape[0], k) + mean.shape[2:])

    return {"toy": jax.jit(sample)}


register(Method(name="toy", config_type=ToyConfig, stages=stages, predictors=predictors), replace=True)


def get_config():
    return Config(name="toy", method="toy", method_config=ToyConfig(num_steps=NSTEPS), eval_k=(3,),
                  ckpt_every=10, log_every=10, max_test_windows=16, eval_batch=16)
'''


@pytest.mark.slow
def test_a_registered_method_trains_resumes_and_evaluates_through_the_one_runner(tmp_path):
    half, full = tmp_path / "half.py", tmp_path / "full.py"
    half.write_text(TOY.replace("NSTEPS", "20"))
    full.write_text(TOY.replace("NSTEPS", "40"))
    assert main(["train", "--config", str(half), "--workdir", str(tmp_path / "a")]) == 0
    # The computed stage was made from the 20-step velocity: once that trains on, it is stale, and said so.
    with pytest.raises(CheckpointMismatch, match=r"stage 'spread'.*trained on stage 'velocity' at step 20, which is now at step 40"):
        main(["run", "--config", str(full), "--workdir", str(tmp_path / "a"), "--resume"])
    shutil.rmtree(tmp_path / "a" / "spread")
    assert main(["run", "--config", str(full), "--workdir", str(tmp_path / "a"), "--resume"]) == 0
    assert main(["run", "--config", str(full), "--workdir", str(tmp_path / "b")]) == 0
    log = [json.loads(line) for line in (tmp_path / "a" / "velocity" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [10, 20, 30, 40] and log[-1]["mse"] < log[0]["mse"]
    cfg = load_config(full)
    prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
    va = experiment.restore(cfg, prep, tmp_path / "a")["velocity"]["v"]
    vb = experiment.restore(cfg, prep, tmp_path / "b")["velocity"]["v"]
    np.testing.assert_array_equal(np.asarray(va), np.asarray(vb))  # Adam at a constant lr: resume is exact
    assert float(np.abs(np.asarray(va)).max()) > 0
    spread = experiment.restore(cfg, prep, tmp_path / "a")["spread"]["s"]
    assert float(spread) == pytest.approx(float(np.abs(np.asarray(va)).mean()) + 0.01, rel=1e-6)
    records = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert [(r["method"], r["K"]) for r in records] == [("toy", 3)]
    assert records[0]["metrics"]["APD"] > 0 and np.isfinite(records[0]["metrics"]["ADE"])
    assert main(["methods"]) == 0


def test_register_refuses_a_second_method_of_the_same_name_and_a_non_method():
    m = Method(name="twice", config_type=dict, stages=lambda c, p: [], predictors=lambda c, d, p, k: {})
    register(m)
    with pytest.raises(ValueError, match="already registered"):
        register(Method(name="twice", config_type=dict, stages=lambda c, p: [], predictors=lambda c, d, p, k: {}))
    with pytest.raises(TypeError, match="Method"):
        register("dlow")
    with pytest.raises(ValueError, match="reference_futures"):
        Method(name="x", config_type=dict, stages=m.stages, predictors=m.predictors, reference_futures="elsewhere")
    init, tx = (lambda key, frozen: {}), optax.sgd(0.1)
    with pytest.raises(ValueError, match="folder name"):
        Stage(name="a/b", init=init, optimizer=tx, loss=None, batches=None, num_steps=0)
    with pytest.raises(ValueError, match="needs a loss and batches"):
        Stage(name="a", init=init, optimizer=tx, loss=None, batches=None, num_steps=3)
    assert experiment.resolve(Config(method="twice", method_config={})).method_config == {}


def test_reference_futures_from_training_windows():
    import dataclasses

    ds = experiment.load_data(Config())
    # Training on the test sequences themselves: every test window is also a training window.
    prep = experiment.prepare(dataclasses.replace(ds, train=ds.test), 20)
    stub = dict(config_type=dict, stages=lambda c, p: [], predictors=lambda c, d, p, k: {})
    from jaxmotion.eval import mm_source, reference

    cfg = Config()
    (idx, mask), none = reference(mm_source(cfg, Method(name="t", **stub))).build(prep)[1:3]
    assert none is None and int(np.asarray(idx).max()) < len(prep.windows)
    (idx, mask), futures = reference(mm_source(cfg, Method(name="t", reference_futures="train", **stub))).build(prep)[1:3]
    idx, mask = np.asarray(idx), np.asarray(mask)
    assert futures.shape[1:] == (ds.t_pred, ds.dim) and len(futures) > len(prep.windows)
    for i in range(len(prep.windows)):
        members = futures[idx[i][mask[i]]]
        assert len(members) > 0 and np.abs(members - prep.y[i]).max(axis=(1, 2)).min() == 0.0  # its own future is among them


def test_a_computed_stage_is_restored_not_computed_again(tmp_path):
    import jax.numpy as jnp

    from jaxmotion.train import runner

    calls = []

    def computed(key, frozen):  # stands for an expensive computation (MotionMap's t-SNE codebook)
        calls.append(1)
        return {"s": frozen["fit"]["w"].sum() + 1.0}

    def stages(cfg, prep):
        fit = Stage(name="fit", init=lambda key, _f: {"w": jnp.zeros(3)}, optimizer=optax.sgd(0.1),
                    loss=lambda p, _f, b, key: (jnp.sum((p["w"] - b) ** 2), {}),
                    batches=lambda rng: np.ones((2, 3), np.float32), num_steps=2)
        return [fit, Stage(name="stats", init=computed, optimizer=optax.set_to_zero(), loss=None, batches=None,
                           num_steps=0, frozen=("fit",))]

    method = Method(name="computed_toy", config_type=dict, stages=stages, predictors=lambda *a: {})
    cfg = Config(ckpt_every=1, log_every=1)
    first = runner.train(method, cfg, None, tmp_path)
    assert len(calls) == 1
    again = runner.train(method, cfg, None, tmp_path, resume=True)
    restored = runner.restore(method, cfg, None, tmp_path)
    assert len(calls) == 1  # neither the resumed run nor the restore computed it again
    for params in (again, restored):
        np.testing.assert_allclose(np.asarray(params["stats"]["s"]), np.asarray(first["stats"]["s"]))


def test_learning_curve_takes_its_mm_ground_truth_from_the_config():
    """`learning_curve` scores MMADE against the evaluation's source (`Config.mm_ground_truth`), not always the method's own."""
    import dataclasses

    from jaxmotion.eval import metrics
    from jaxmotion.eval import learning_curve, reference
    from jaxmotion.methods import get_method
    from jaxmotion.methods.common import zero_velocity

    register(Method(name="curve_stub", config_type=dict, stages=lambda c, p: [],
                    predictors=lambda c, d, p, k: {"zv": zero_velocity(d.t_pred, k)}))  # fmt: skip
    ds = experiment.load_data(Config())
    # Training on the test sequences themselves, so that training windows match test windows (finite MMADE).
    prep = experiment.prepare(dataclasses.replace(ds, train=ds.test), 40)
    base = Config(method="curve_stub", method_config={}, curve_k=2, curve_windows=10)
    sub = np.unique(np.linspace(0, len(prep.windows) - 1, 10).round().astype(int))
    x = prep.x[sub]
    pred = np.broadcast_to(x[:, None, -1:], (len(sub), 2, ds.t_pred, ds.dim))
    got = {}
    for source in (None, "train", "motionmap-train"):
        point = learning_curve(dataclasses.replace(base, mm_ground_truth=source), get_method("curve_stub"), prep)({})["predictors"]["zv"]
        r = reference(source or "test").build(prep)
        sets = metrics.MMSets(np.asarray(r.sets.idx)[sub], np.asarray(r.sets.mask)[sub])
        transfer = {} if r.transfer_parents is None else dict(transfer_poses=r.transfer_poses[sub], transfer_parents=r.transfer_parents)
        want = evaluate_windows(iter([pred]), prep.y[sub], sets,
                                        reference_futures=prep.y if r.futures is None else r.futures, **transfer)  # fmt: skip
        assert np.isfinite(point["MMADE"]) and point["MMADE"] == pytest.approx(float(want["MMADE"]), abs=1e-6), source
        got[source] = point["MMADE"]
    assert got["motionmap-train"] != got[None]  # another reference set: the curve moves with the source
