"""Initialisation of every layer of every model against its reference's rule.

Dense layers: every model's are PyTorch's `nn.Linear`, U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for weight
and bias (`Dense(rule="torch")`); `Dense(rule="flax")` is `nn.Dense`, lecun-normal weights (variance
1/fan_in) and zero biases.
GRUs always follow PyTorch's `nn.GRU` (U(+-1/sqrt(hidden)) for all four tensors); DivSamp's graph
convolutions its release (U(+-1/sqrt(out_features)) for weight, adjacency and bias).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.models import divsamp, dlow, mojo
from jaxmotion.nn.linear import Dense

D, T_HIS, T_PRED = 12, 5, 8


def _dense_layers(tree, path=()):
    """Yields `(path, kernel, bias)` for every dense layer (a dict with a 2-D kernel and a bias, no adjacency)."""
    if isinstance(tree, dict):
        if "kernel" in tree and "bias" in tree and "adjacency" not in tree and np.ndim(tree["kernel"]) == 2:
            yield path, np.asarray(tree["kernel"]), np.asarray(tree["bias"])
        for k, v in tree.items():
            yield from _dense_layers(v, path + (k,))


def _gru_cells(tree, path=()):
    if isinstance(tree, dict):
        if "weight_ih" in tree:
            yield path, tree
        for k, v in tree.items():
            yield from _gru_cells(v, path + (k,))


def _check_dense(layers):
    """Every layer's weight and bias U(-1/sqrt(fan_in), 1/sqrt(fan_in)), as PyTorch's nn.Linear."""
    layers = list(layers)
    assert layers, "no dense layer found"
    for path, w, b in layers:
        bound = 1.0 / math.sqrt(w.shape[0])
        assert np.abs(w).max() <= bound and np.abs(b).max() <= bound, path
        if w.size >= 2000:  # uniform: std = bound / sqrt(3)
            assert np.std(w) == pytest.approx(bound / math.sqrt(3), rel=0.1), path
            assert np.abs(w).max() > 0.95 * bound, path


def _gru_ok(params):
    cells = list(_gru_cells(params))
    assert cells
    for path, c in cells:
        bound = 1.0 / math.sqrt(c["weight_hh"].shape[0])
        for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
            a = np.asarray(c[name])
            assert np.abs(a).max() <= bound, (path, name)
        assert np.std(np.asarray(c["weight_hh"])) == pytest.approx(bound / math.sqrt(3), rel=0.15), path


def _dlow_params():
    c = dlow.CVAEConfig(nz=16, nh_rnn=64, nh_mlp=(128, 64))
    cvae = dlow.cvae_model(c, D, T_PRED)
    x, y = jnp.zeros((1, T_HIS, D)), jnp.zeros((1, T_PRED, D))
    q = dlow.q_model(dlow.QConfig(nh_rnn=64, nh_mlp=(128, 64)), 16, 5)
    return cvae.init(jax.random.key(0), x, y)["params"], q.init(jax.random.key(1), x, jnp.zeros((1, 16)))["params"]


def _mojo_params():
    m = mojo.MojoConfig(nz=8, nh_rnn=64, nh_mlp=(128, 64), q_nh_rnn=64, q_nh_mlp=(128, 64))
    model, q = mojo.cvae_model(m, D, T_PRED), mojo.q_model(m, T_PRED, 5)
    x, y = jnp.zeros((1, T_HIS, D)), jnp.zeros((1, T_PRED, D))
    return model.init(jax.random.key(0), x, y)["params"], q.init(jax.random.key(1), x, jnp.zeros((1, q.n_low, 8)))["params"]


def _divsamp_params():
    d = divsamp.check_config(divsamp.DivSampConfig(hidden=32, nz=8, num_bases=4, base_dim=16, nh=16, cvae_residual=1, sampler_residual=1))
    cvae, sampler = divsamp.cvae_from_config(d), divsamp.sampler_from_config(d)
    cx = jnp.zeros((2, D // 3, 3 * d.n_dct))
    cv = cvae.init(jax.random.key(0), cx, cx, jax.random.key(1), train=False)["params"]
    sv = sampler.init(jax.random.key(2), cx, jax.random.key(3), 3, train=False)["params"]
    return cv, sv


@pytest.mark.parametrize("build", [_dlow_params, _mojo_params, _divsamp_params], ids=["dlow", "mojo", "divsamp"])
@pytest.mark.slow
def test_every_dense_layer_follows_pytorch(build):
    for params in build():
        _check_dense(_dense_layers(params))


@pytest.mark.parametrize("build", [_dlow_params, _mojo_params], ids=["dlow", "mojo"])
@pytest.mark.slow
def test_grus_follow_pytorch(build):
    for params in build():
        _gru_ok(params)


@pytest.mark.slow
def test_divsamp_graph_convolutions_follow_the_release():
    cv, sv = _divsamp_params()
    convs = [(p, t) for p, t in _walk(cv) if "adjacency" in t]
    assert convs
    for path, t in convs:
        bound = 1.0 / math.sqrt(t["kernel"].shape[1])
        for name in ("kernel", "adjacency"):
            assert np.abs(np.asarray(t[name])).max() <= bound, (path, name)


def _walk(tree, path=()):
    if isinstance(tree, dict):
        yield path, tree
        for k, v in tree.items():
            yield from _walk(v, path + (k,))


def test_flax_rule_is_bit_for_bit_flax_dense():
    import flax.linen as nn

    x = jax.random.normal(jax.random.key(5), (3, 40))
    ours = Dense(24, rule="flax").init(jax.random.key(6), x)
    ref = nn.Dense(24).init(jax.random.key(6), x)
    for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(ref)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(Dense(24, rule="flax").apply(ours, x)), np.asarray(nn.Dense(24).apply(ref, x)))
    with pytest.raises(ValueError, match="Dense.rule"):
        Dense(3, rule="kaiming").init(jax.random.key(0), x)


def test_torch_rule_matches_a_fresh_pytorch_linear():
    torch = pytest.importorskip("torch")
    torch.manual_seed(0)
    lin = torch.nn.Linear(300, 200)
    tw, tb = lin.weight.detach().numpy(), lin.bias.detach().numpy()
    p = Dense(200, rule="torch").init(jax.random.key(0), jnp.zeros((1, 300)))["params"]
    w, b = np.asarray(p["kernel"]), np.asarray(p["bias"])
    assert w.shape == tw.T.shape and b.shape == tb.shape
    assert np.abs(w).max() <= 1 / math.sqrt(300) and np.abs(tw).max() <= 1 / math.sqrt(300)
    assert np.std(w) == pytest.approx(np.std(tw), rel=0.05)
    assert np.std(b) == pytest.approx(np.std(tb), rel=0.3)
    assert np.abs(b).max() == pytest.approx(np.abs(tb).max(), rel=0.05)


def _motionmap_params():
    from jaxmotion.models import motionmap as mm

    c = mm.MotionMapConfig(nh_rnn=32, nh_fuse=64, nh_uncertainty=64, n_uncertainty_layers=2, hm_size=16)
    ae, hm = mm.ae_model(c, D, T_HIS, T_PRED), mm.heatmap_model(c)
    x, y = jnp.zeros((2, T_HIS, D)), jnp.zeros((2, T_PRED, D))
    return ae.init(jax.random.key(0), x, y)["params"], hm.init(jax.random.key(1), x)["params"]


def _gsps_params():
    from jaxmotion.models import gsps

    gen = gsps.GSPSGenerator(parts=((0, 1), (2, 3)), hidden=32, num_stage=1)
    nodes, z = jnp.zeros((2, 4, 30)), jnp.zeros((2, 2, 8))
    return gen.init(jax.random.key(0), nodes, z, train=False)["params"]


@pytest.mark.slow
def test_motionmap_dense_and_conv_layers_follow_pytorch():
    ae, hm = _motionmap_params()
    _check_dense(_dense_layers(ae))
    _check_dense(_dense_layers(hm))
    convs = [(p, t) for p, t in _walk(hm) if "kernel" in t and np.ndim(t["kernel"]) == 4]
    assert len(convs) == 7
    for path, t in convs:
        w, b = np.asarray(t["kernel"]), np.asarray(t["bias"])
        bound = 1.0 / math.sqrt(w.shape[2])  # 1x1: fan_in = input channels (PyTorch nn.Conv2d)
        assert np.abs(w).max() <= bound and np.abs(b).max() <= bound and np.any(b != 0), path
    _gru_ok(ae)


@pytest.mark.slow
def test_gsps_graph_convolutions_follow_the_release():
    convs = [(p, t) for p, t in _walk(_gsps_params()) if "adjacency" in t]
    assert len(convs) == 2 * 4  # per part: gcl_in, two in the residual pair, out
    for path, t in convs:
        bound = 1.0 / math.sqrt(t["kernel"].shape[1])
        for name in ("kernel", "adjacency", "bias"):
            a = np.asarray(t[name])
            assert np.abs(a).max() <= bound, (path, name)
            assert np.std(a) == pytest.approx(bound / math.sqrt(3), rel=0.35), (path, name)


def test_the_default_rule_is_pytorchs():
    assert Dense(3).rule == "torch"
