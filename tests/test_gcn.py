"""Graph convolutions with a learnable adjacency and GCL-BN-Tanh stacks (jaxmotion.nn.gcn)."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.nn.gcn import GCLBlock, GCLStack, GraphConv, ResidualGCLBlock

J, F = 5, 4


def _h(b=6, seed=0):
    return jnp.asarray(np.random.default_rng(seed).normal(size=(b, J, F)), jnp.float32)


def test_graph_conv_is_a_h_w_plus_b():
    layer = GraphConv(3)
    h = _h()
    p = layer.init(jax.random.key(0), h)["params"]
    a, w, b = (np.asarray(p[n]) for n in ("adjacency", "kernel", "bias"))
    ref = np.einsum("ij,bjf,fo->bio", a, np.asarray(h), w) + b
    np.testing.assert_allclose(np.asarray(layer.apply({"params": p}, h)), ref, atol=1e-5)
    # Every joint's output depends on every joint's input through the dense, learned A.
    jac = jax.jacobian(lambda x: layer.apply({"params": p}, x)[0, 0].sum())(h)
    assert np.all(np.abs(np.asarray(jac)[0]).sum(axis=-1) > 0)
    # The release's initialisation: U(-1/sqrt(F_out), 1/sqrt(F_out)) for A, W and b.
    assert np.abs(a).max() <= 1 / np.sqrt(3) and np.abs(w).max() <= 1 / np.sqrt(3)


def test_graph_conv_maps_any_leading_axes():
    layer = GraphConv(3)
    h = _h(b=12).reshape(3, 4, J, F)
    p = layer.init(jax.random.key(0), h)
    flat = layer.apply(p, h.reshape(12, J, F))
    np.testing.assert_allclose(np.asarray(layer.apply(p, h)).reshape(12, J, 3), np.asarray(flat), atol=1e-6)


def test_repeated_rows_give_the_full_batchs_statistics():
    # BatchNorm's `repeats`: g rows standing for r equal copies each normalise and update the running
    # averages as the g * r rows would (the unbiased variance counts g * r values).
    block = GCLBlock(3)
    h = _h(b=8, seed=2)
    v = block.init(jax.random.key(0), h, train=False)
    full, s_full = block.apply(v, jnp.repeat(h, 5, axis=0), train=True, mutable=["batch_stats"])
    once, s_once = block.apply(v, h, train=True, repeats=5, mutable=["batch_stats"])
    np.testing.assert_allclose(jnp.repeat(once, 5, axis=0), full, atol=1e-6)
    for a, b in zip(jax.tree.leaves(s_once), jax.tree.leaves(s_full)):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


def test_batchnorm_train_mode_normalises_and_updates_running_averages():
    block = GCLBlock(3)
    h = _h(b=64, seed=1)
    v = block.init(jax.random.key(0), h, train=False)
    out, upd = block.apply(v, h, train=True, mutable=["batch_stats"])
    pre = np.arctanh(np.clip(np.asarray(out), -0.999999, 0.999999)).reshape(64, -1)
    # Per (joint, feature): batch mean 0, batch variance 1 (BN scale 1 and bias 0 at init).
    np.testing.assert_allclose(pre.mean(0), 0.0, atol=1e-3)
    np.testing.assert_allclose(pre.var(0), 1.0, atol=2e-2)
    gc = GraphConv(3).apply({"params": v["params"]["gc"]}, h).reshape(64, -1)
    # PyTorch momentum 0.1: running = 0.9 * running + 0.1 * batch statistic; the variance unbiased, as PyTorch keeps it.
    np.testing.assert_allclose(np.asarray(upd["batch_stats"]["bn"]["mean"]), 0.1 * np.asarray(gc.mean(0)), atol=1e-5)
    np.testing.assert_allclose(np.asarray(upd["batch_stats"]["bn"]["var"]), 0.9 + 0.1 * np.asarray(gc).var(0, ddof=1), rtol=1e-3)


def test_eval_mode_uses_running_averages_so_samples_are_independent():
    block = GCLBlock(3)
    h = _h(b=8, seed=2)
    v = block.init(jax.random.key(0), h, train=False)
    _, upd = block.apply(v, h, train=True, mutable=["batch_stats"])
    v = {"params": v["params"], **upd}
    full = block.apply(v, h, train=False)
    one = block.apply(v, h[3:4], train=False)
    np.testing.assert_allclose(np.asarray(full[3:4]), np.asarray(one), atol=1e-6)
    st = v["batch_stats"]["bn"]
    gc = GraphConv(3).apply({"params": v["params"]["gc"]}, h).reshape(8, -1)
    ref = np.tanh((np.asarray(gc) - np.asarray(st["mean"])) / np.sqrt(np.asarray(st["var"]) + 1e-5))
    np.testing.assert_allclose(np.asarray(full).reshape(8, -1), ref, atol=1e-5)


def test_stack_depth_and_residual():
    stack = GCLStack(8, num_residual=4)
    h = _h()
    v = stack.init(jax.random.key(0), h, train=False)
    n_bn = len([p for p in jax.tree_util.tree_leaves_with_path(v["batch_stats"]) if p[0][-1].key == "mean"])
    assert n_bn == 9  # DivSamp's CVAE encoder / decoder: 9 GCL-BN-Tanh layers
    assert stack.apply(v, h, train=False).shape == (6, J, 8)


def test_residual_block_adds_its_input():
    block = ResidualGCLBlock(F)
    h = _h(b=8, seed=3)
    v = block.init(jax.random.key(0), h, train=False)
    p, st = v["params"], v["batch_stats"]
    inner = GCLBlock(F).apply({"params": p["gcl_0"], "batch_stats": st["gcl_0"]}, h, train=False)
    inner = GCLBlock(F).apply({"params": p["gcl_1"], "batch_stats": st["gcl_1"]}, inner, train=False)
    out = block.apply(v, h, train=False)
    # H + GCL(GCL(H)): the skip connection, exactly.
    np.testing.assert_allclose(np.asarray(out), np.asarray(h + inner), atol=1e-6)
    # The output's Jacobian w.r.t. the input is I + (the two layers' Jacobian): with the inner
    # layers' weights zeroed only the identity is left.
    zero = jax.tree_util.tree_map(jnp.zeros_like, p)
    out0 = block.apply({"params": zero, "batch_stats": st}, h, train=False)
    np.testing.assert_allclose(np.asarray(out0), np.asarray(h), atol=1e-6)


def test_node_major_stack_equals_batch_major_in_outputs_statistics_and_gradients():
    # GCLStack runs node-major by default; the batch-major layout is the reference definition.
    h = _h(b=12, seed=4).reshape(3, 4, J, F)  # two leading axes, as DivSamp's (b, K) samples
    fast, ref = GCLStack(8, num_residual=2), GCLStack(8, num_residual=2, node_major=False)
    v = ref.init(jax.random.key(0), h, train=False)
    assert jax.tree.map(jnp.shape, fast.init(jax.random.key(0), h, train=False)) == jax.tree.map(jnp.shape, v)
    for train in (False, True):
        out_f, st_f = fast.apply(v, h, train=train, mutable=["batch_stats"])
        out_r, st_r = ref.apply(v, h, train=train, mutable=["batch_stats"])
        np.testing.assert_allclose(np.asarray(out_f), np.asarray(out_r), atol=1e-5)
        jax.tree.map(lambda a, b: np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-5), st_f, st_r)

    def loss(m, p):
        out, _ = m.apply({"params": p, "batch_stats": v["batch_stats"]}, h, train=True, mutable=["batch_stats"])
        return jnp.sum(jnp.sin(out))

    g_f, g_r = jax.grad(lambda p: loss(fast, p))(v["params"]), jax.grad(lambda p: loss(ref, p))(v["params"])
    jax.tree.map(lambda a, b: np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-4), g_f, g_r)
