"""nn.BatchNorm: PyTorch's running statistics (unbiased running variance) under flax's names."""

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.nn.batchnorm import BatchNorm


def _steps(module, xs):
    v = module.init(jax.random.key(0), xs[0])
    outs = []
    for x in xs:
        y, upd = module.apply(v, x, mutable=["batch_stats"])
        v = {**v, **upd}
        outs.append(np.asarray(y))
    return v, outs


def _batches(n=4, b=16, f=5, seed=0):
    rng = np.random.default_rng(seed)
    return [jnp.asarray(rng.normal(2.0, 3.0, (b, f)), jnp.float32) for _ in range(n)]


def test_unbiased_running_variance_by_hand():
    xs = _batches(n=1)
    v, (y,) = _steps(BatchNorm(use_running_average=False), xs)
    x = np.asarray(xs[0])
    np.testing.assert_allclose(np.asarray(v["batch_stats"]["var"]), 0.9 + 0.1 * x.var(0, ddof=1), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(v["batch_stats"]["mean"]), 0.1 * x.mean(0), rtol=1e-5, atol=1e-6)
    # the batch itself is normalised by its biased variance, as in both frameworks
    np.testing.assert_allclose(y, (x - x.mean(0)) / np.sqrt(x.var(0) + 1e-5), rtol=1e-4, atol=1e-5)


def test_flax_batchnorm_names_and_batch_outputs_only_the_running_variance_differs():
    xs = _batches()
    ours, yo = _steps(BatchNorm(use_running_average=False), xs)
    ref, yr = _steps(nn.BatchNorm(use_running_average=False, momentum=0.9, epsilon=1e-5), xs)
    assert jax.tree.structure(ours) == jax.tree.structure(ref)  # same names: checkpoints load either way
    np.testing.assert_allclose(yo[-1], yr[-1], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(ours["batch_stats"]["mean"], ref["batch_stats"]["mean"], rtol=1e-5, atol=1e-6)
    # flax keeps the biased batch variance, PyTorch (and this layer) the unbiased one: n / (n - 1) = 16 / 15 larger.
    excess = (np.asarray(ours["batch_stats"]["var"]) - 0.9 ** len(xs)) / (np.asarray(ref["batch_stats"]["var"]) - 0.9 ** len(xs))
    np.testing.assert_allclose(excess, 16 / 15, rtol=1e-4)


def test_leading_axes_all_count_and_evaluation_uses_running_stats():
    x = jnp.asarray(np.random.default_rng(1).normal(size=(4, 3, 6)), jnp.float32)  # (b, K, f): n = 12
    v, _ = _steps(BatchNorm(use_running_average=False), [x])
    flat = np.asarray(x).reshape(-1, 6)
    np.testing.assert_allclose(np.asarray(v["batch_stats"]["var"]), 0.9 + 0.1 * flat.var(0, ddof=1), rtol=1e-5)
    y = BatchNorm(use_running_average=True).apply(v, x)
    bs = v["batch_stats"]
    np.testing.assert_allclose(np.asarray(y).reshape(-1, 6), (flat - bs["mean"]) / np.sqrt(bs["var"] + 1e-5), rtol=1e-4, atol=1e-5, err_msg="eval")


def test_matches_pytorch_batchnorm1d():
    torch = pytest.importorskip("torch")
    xs = _batches(n=5, b=16, f=7, seed=3)
    v, ys = _steps(BatchNorm(use_running_average=False), xs)
    bn = torch.nn.BatchNorm1d(7, momentum=0.1, eps=1e-5)
    bn.train()
    for x, y in zip(xs, ys):
        t = bn(torch.from_numpy(np.array(x))).detach().numpy()
        np.testing.assert_allclose(y, t, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(np.asarray(v["batch_stats"]["mean"]), bn.running_mean.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(v["batch_stats"]["var"]), bn.running_var.numpy(), rtol=1e-5)
    bn.eval()
    x = xs[0]
    np.testing.assert_allclose(
        np.asarray(BatchNorm(use_running_average=True).apply(v, x)), bn(torch.from_numpy(np.array(x))).detach().numpy(), rtol=1e-4, atol=1e-5
    )


_PER_DEVICE_WORKER = r'''
import json, sys
import jax, jax.numpy as jnp, numpy as np, optax
from jaxmotion.nn.batchnorm import BatchNorm
from jaxmotion.train.distributed import data_mesh
from jaxmotion.train.loop import bn_optimizer, create_state, make_bn_train_step

x = jnp.asarray(np.random.default_rng(0).normal(1.0, 2.0, (8, 3)), jnp.float32)
out = {}
for per_device in (False, True):
    bn = BatchNorm(use_running_average=False, per_device=per_device)
    def loss(v, _frozen, batch, _key):
        y, upd = bn.apply(v, batch, mutable=["batch_stats"])
        return jnp.mean(y ** 3 + y), ({}, upd["batch_stats"])
    v = bn.init(jax.random.key(0), x)
    step = make_bn_train_step(loss, bn_optimizer(optax.sgd(0.1)), mesh=data_mesh())
    state = create_state(v, bn_optimizer(optax.sgd(0.1)))
    hlo = jax.jit(step).lower(state, x, jax.random.key(0)).compile().as_text()
    new, m = jax.jit(step)(state, x, jax.random.key(0))
    out[str(per_device)] = {"loss": float(m["loss"]), "stats": jax.tree.map(lambda a: np.asarray(a).tolist(), new.params["batch_stats"]),
                            "all_reduces": hlo.count(" all-reduce(") + hlo.count(" all-reduce-start(")}
# Each device's rows alone, on one device: the reference of the per-device mode.
bn = BatchNorm(use_running_average=False)
v = bn.init(jax.random.key(0), x)
halves = [bn.apply(v, h, mutable=["batch_stats"]) for h in (x[:4], x[4:])]
out["halves"] = {"loss": float(np.mean([jnp.mean(y ** 3 + y) for y, _ in halves])),
                 "stats": jax.tree.map(lambda *a: np.mean(a, axis=0).tolist(), *[u["batch_stats"] for _, u in halves])}
json.dump(out, open(sys.argv[1], "w"))
'''


def test_per_device_moments_normalise_each_devices_rows_with_one_all_reduce_per_step(tmp_path):
    """`BatchNorm(per_device=True)` on 2 devices: each device normalises its own rows (the loss is the mean of
    the two halves' losses on one device), the running statistics are the two halves' averaged, and the step
    has one all-reduce (the default, global moments, has one per moment besides)."""
    import os
    import subprocess
    import sys

    from jaxmotion.train.host_devices import host_device_env

    env = dict(host_device_env(os.environ, 2), JAX_PLATFORMS="cpu")  # keeps the session's flags
    out = tmp_path / "out.json"
    subprocess.run([sys.executable, "-c", _PER_DEVICE_WORKER, str(out)], env=env, check=True, timeout=300)
    import json

    r = json.loads(out.read_text())
    per, glob, halves = r["True"], r["False"], r["halves"]
    assert per["all_reduces"] == 1 and glob["all_reduces"] > 1
    np.testing.assert_allclose(per["loss"], halves["loss"], rtol=1e-5)
    for key in ("mean", "var"):
        np.testing.assert_allclose(per["stats"][key], halves["stats"][key], rtol=1e-5, atol=1e-6)
    assert abs(per["loss"] - glob["loss"]) > 1e-4  # the two modes differ on several devices
