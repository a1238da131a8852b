"""DLow models, objectives and samplers: properties that fail if the maths is wrong."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion import losses
from jaxmotion.models import dlow
from jaxmotion.models.cvae import GRUCVAE
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.gru import GRU, GRUCell, gru_gates, gru_update, gru_update_backward

D, T_HIS, T_PRED, B = 6, 4, 5, 3


@pytest.fixture(scope="module")
def cvae():
    model = dlow.DLowCVAE(dim=D, horizon=T_PRED, nz=8, nh_rnn=16, nh_mlp=(20, 12))
    x = jnp.asarray(np.random.default_rng(0).normal(size=(B, T_HIS, D)), jnp.float32)
    y = jnp.asarray(np.random.default_rng(1).normal(size=(B, T_PRED, D)), jnp.float32)
    params = model.init(jax.random.key(0), x, y, jax.random.key(1))
    return model, params, x, y


def test_gru_cell_matches_pytorch_equations():
    cell = GRUCell(4)
    h = jnp.asarray(np.random.default_rng(0).normal(size=(2, 4)), jnp.float32)
    x = jnp.asarray(np.random.default_rng(1).normal(size=(2, 3)), jnp.float32)
    p = cell.init(jax.random.key(0), h, x)["params"]
    sig = lambda v: 1 / (1 + np.exp(-v))
    gi = np.asarray(x) @ np.asarray(p["weight_ih"]) + np.asarray(p["bias_ih"])
    gh = np.asarray(h) @ np.asarray(p["weight_hh"]) + np.asarray(p["bias_hh"])
    r = sig(gi[:, :4] + gh[:, :4])
    z = sig(gi[:, 4:8] + gh[:, 4:8])
    n = np.tanh(gi[:, 8:] + r * gh[:, 8:])
    ref = (1 - z) * n + z * np.asarray(h)
    np.testing.assert_allclose(np.asarray(cell.apply({"params": p}, h, x)), ref, atol=1e-5)


def test_scanned_gru_equals_a_python_loop_of_cells():
    gru = GRU(5)
    x = jnp.asarray(np.random.default_rng(2).normal(size=(2, 7, 3)), jnp.float32)
    p = gru.init(jax.random.key(0), x)
    hs = gru.apply(p, x)
    cell = GRUCell(5)
    h = jnp.zeros((2, 5))
    for t in range(7):
        h = cell.apply({"params": p["params"]["cell"]}, h, x[:, t])
        np.testing.assert_allclose(np.asarray(hs[:, t]), np.asarray(h), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(gru.apply(p, x, last_only=True)), np.asarray(hs[:, -1]))


def test_cvae_forward_and_gradients_equal_the_unshared_past_code(cvae):
    """`__call__` encodes the past once for the encoder and the decoder: the same numbers as encoding it twice."""
    model, params, x, y = cvae
    key = jax.random.key(3)

    def shared(p):
        return model.apply(p, x, y, key)

    def twice(p):  # the definition: encode (which encodes the past itself), then decode (which does again)
        mu, logvar = model.apply(p, x, y, method=dlow.DLowCVAE.encode)
        z = mu + jnp.exp(0.5 * logvar) * jax.random.normal(key, mu.shape)
        return model.apply(p, x, z, method=dlow.DLowCVAE.decode), mu, logvar

    for a, b in zip(shared(params), twice(params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-6)
    loss = lambda f: lambda p: sum(jnp.sum(o ** 2) for o in f(p))
    ga, gb = jax.grad(loss(shared))(params), jax.grad(loss(twice))(params)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-6), ga, gb)


def test_decoder_scan_equals_step_by_step_decoding(cvae):
    model, params, x, _ = cvae
    z = jnp.ones((B, 8))
    ys = model.apply(params, x, z, method=dlow.DLowCVAE.decode)
    carry, inputs = model.apply(params, x, z, method=dlow.DLowCVAE.decode_init)
    for t in range(T_PRED):
        step_in = jax.tree.map(lambda a: a[t], inputs)
        np.testing.assert_array_equal(np.asarray(step_in.z_t), np.asarray(z))  # a vector latent is the same every step
        carry, y_t = model.apply(params, carry, step_in, method=dlow.DLowCVAE.decode_step)
        np.testing.assert_allclose(np.asarray(ys[:, t]), np.asarray(y_t), atol=1e-5)
        # Autoregressive: the next step is fed the frame just predicted.
        np.testing.assert_array_equal(np.asarray(carry.y_prev), np.asarray(y_t))


def test_gru_update_backward_equals_the_chain_rule_of_gru_update():
    """The hand-written GRU backward of the decoder loop (from the forward pass's gates) gives jax's cotangents."""
    rng = np.random.default_rng(0)
    gi, gh = (jnp.asarray(rng.normal(size=(5, 12)), jnp.float32) for _ in range(2))
    h, dh2 = (jnp.asarray(rng.normal(size=(5, 4)), jnp.float32) for _ in range(2))
    _, vjp = jax.vjp(gru_update, gi, gh, h)
    for want, got in zip(vjp(dh2), gru_update_backward(dh2, gru_gates(gi, gh), h), strict=True):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-6, atol=1e-6)


def test_frozen_decoder_latent_gradient_equals_autodiff():
    """DLow's Q step: K latents decoded by a frozen decoder (vmapped over K, parameters stop-gradiented), the
    gradient reaching the latents alone (the weight-gradient products dropped) equals differentiating the loop."""
    model = GRUCVAE(dim=D, horizon=T_PRED, nz=8, nh_rnn=16, nh_mlp=(20, 12))
    x = jnp.asarray(np.random.default_rng(1).normal(size=(B, T_HIS, D)), jnp.float32)
    params = model.init(jax.random.key(0), x, jnp.zeros((B, T_PRED, D)), jax.random.key(1))
    z = jax.random.normal(jax.random.key(2), (B, 5, 8))
    target = jax.random.normal(jax.random.key(3), (B, 5, T_PRED, D))

    def grad_z(m):
        loss = lambda z: jnp.sum((dlow.decode_k(m, jax.lax.stop_gradient(params), x, z) - target) ** 2)  # noqa: E731
        return jax.jit(jax.value_and_grad(loss))(z)

    l_ref, g_ref = grad_z(model.clone(execution=Execution(decoder_backward="autodiff")))
    l_new, g_new = grad_z(model)
    np.testing.assert_allclose(float(l_new), float(l_ref), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(g_new), np.asarray(g_ref), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("latent,residual", [("vector", False), ("dct", True), ("dct", False)])  # DLow, MOJO, and one more
def test_decoder_backward_remat_and_unroll_give_the_same_futures_and_gradients(latent, residual):
    """The execution choices (nn/execution.py) of the batched backward pass (`decoder_backward="batched"`,
    nn/decoder_loop.py: each weight's gradient one product after the loop), and with autodiff `decoder_remat`
    and `decoder_unroll`, change speed, not numbers: the loss and every gradient (parameters and latent) as
    differentiating the loop gives them."""
    model = GRUCVAE(dim=D, horizon=T_PRED, nz=8, nh_rnn=16, nh_mlp=(20, 12), latent=latent, residual=residual)
    x = jnp.asarray(np.random.default_rng(0).normal(size=(B, T_HIS, D)), jnp.float32)
    params = model.init(jax.random.key(0), x, jnp.zeros((B, T_PRED, D)), jax.random.key(1))
    z = jax.random.normal(jax.random.key(4), (B,) + model.latent_shape)
    target = jax.random.normal(jax.random.key(5), (B, T_PRED, D))
    weight = jnp.arange(1.0, T_PRED + 1)[None, :, None]  # every step's cotangent different

    def loss_and_grads(m):
        loss = lambda p, z: jnp.sum(weight * (m.apply(p, x, z, method=GRUCVAE.decode) - target) ** 2)  # noqa: E731
        return jax.jit(jax.value_and_grad(loss, argnums=(0, 1)))(params, z)

    ex = model.execution
    assert ex.decoder_backward == "batched" and ex.decoder_remat and ex.decoder_unroll == 1  # the defaults
    run = lambda **choices: model.clone(execution=Execution(**choices))  # noqa: E731
    l_ref, g_ref = loss_and_grads(run(decoder_backward="autodiff"))
    for other in (model, run(decoder_backward="autodiff", decoder_remat=False), run(decoder_backward="autodiff", decoder_unroll=4),
                  run(decoder_backward="autodiff", decoder_unroll=T_PRED)):
        l_other, g_other = loss_and_grads(other)
        np.testing.assert_allclose(float(l_ref), float(l_other), rtol=1e-6)
        for a, b in zip(jax.tree.leaves(g_ref), jax.tree.leaves(g_other), strict=True):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-5)
    assert float(jnp.abs(g_ref[1]).max()) > 0  # the latent's gradient (what DLow's Q network trains on) is not trivially zero
    with pytest.raises(ValueError, match="decoder_backward must be one of"):
        Execution(decoder_backward="manual")
    with pytest.raises(ValueError, match="decoder_unroll must be an integer >= 1"):
        Execution(decoder_unroll=0)


@pytest.mark.slow
def test_sampling_k_by_vmap_equals_loop_and_jit_equals_eager(cvae):
    model, params, x, _ = cvae
    z = jax.random.normal(jax.random.key(3), (B, 4, 8))
    batched = dlow.decode_k(model, params, x, z)
    assert batched.shape == (B, 4, T_PRED, D)
    for k in range(4):
        single = model.apply(params, x, z[:, k], method=dlow.DLowCVAE.decode)
        np.testing.assert_allclose(np.asarray(batched[:, k]), np.asarray(single), atol=1e-5)
    jitted = jax.jit(lambda p, x, z: dlow.decode_k(model, p, x, z))(params, x, z)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(batched), atol=1e-5)


@pytest.mark.slow
def test_dlow_sampler_gives_nk_distinct_futures(cvae):
    model, params, x, _ = cvae
    q = dlow.DLowQ(nz=8, nk=5, nh_rnn=16, nh_mlp=(32, 16))
    qp = q.init(jax.random.key(0), x, jnp.zeros((B, 8)))
    out = dlow.sample_dlow(model, params, q, qp, x, jax.random.key(1))
    assert out.shape == (B, 5, T_PRED, D)
    assert np.all(np.isfinite(np.asarray(out)))
    assert float(jnp.min(jnp.abs(out[:, 0] - out[:, 1]).max(axis=(-2, -1)))) > 0
    z, a, b = q.apply(qp, x, jnp.zeros((B, 8)))
    np.testing.assert_allclose(np.asarray(z), np.asarray(b), atol=1e-6)  # eps = 0 gives the offsets


def test_kl_terms():
    assert float(losses.kld_normal(jnp.zeros(7), jnp.zeros(7))) == pytest.approx(0.0)
    assert float(losses.kld_affine(jnp.ones(7), jnp.zeros(7))) == pytest.approx(0.0)
    # KL(N(1, 1) || N(0, 1)) = 1/2 per dimension.
    assert float(losses.kld_normal(jnp.ones(4), jnp.zeros(4))) == pytest.approx(2.0)
    assert float(losses.kld_affine(jnp.full(3, 2.0), jnp.zeros(3))) == pytest.approx(3 * 0.5 * (4 - 1 - np.log(4)), rel=1e-5)


def test_kld_affine_stays_finite_where_a_crosses_zero():
    # The Q network's scale `a` is a linear output: a zero entry made the release's log(a^2) -inf and
    # a synthetic run's loss inf within three steps (losses.kld_affine's docstring).
    a = jnp.array([0.0, 1e-12, 0.5, -2.0])
    b = jnp.zeros(4)
    val, grad = jax.value_and_grad(lambda a: losses.kld_affine(a, b))(a)
    assert np.isfinite(float(val)) and np.all(np.isfinite(np.asarray(grad)))
    # Away from zero the floor does not change the KL: the exact value of the last two entries.
    exact = -0.5 * sum(1 + np.log(v**2) - v**2 for v in (0.5, -2.0))
    assert float(losses.kld_affine(a[2:], b[2:])) == pytest.approx(exact, rel=1e-6)


@pytest.mark.slow
def test_dlow_diversity_loss():
    same = jnp.zeros((5, 3, 2))
    assert float(losses.dlow_diversity(same, 100.0)) == pytest.approx(1.0)
    # Two samples at squared distance 8: exp(-8 / 4).
    two = jnp.stack([jnp.zeros((2, 2)), jnp.full((2, 2), np.sqrt(2.0))])
    assert float(losses.dlow_diversity(two, 4.0)) == pytest.approx(np.exp(-2.0), rel=1e-5)
    spread = jnp.arange(4.0)[:, None, None] * 100 * jnp.ones((4, 3, 2))
    assert float(losses.dlow_diversity(spread, 1.0)) < 1e-6


def test_min_of_k_picks_the_closest_sample():
    y = jnp.zeros((3, 2))
    yk = jnp.stack([jnp.ones((3, 2)), jnp.full((3, 2), 0.5), jnp.full((3, 2), -2.0)])
    assert float(losses.min_of_k_sq_error(yk, y)) == pytest.approx(6 * 0.25)


def test_cvae_loss_terms(cvae):
    model, params, x, y = cvae
    batch = jnp.concatenate([x, y], axis=1)
    loss, m = dlow.cvae_loss(model, params, batch, jax.random.key(0), t_his=T_HIS, beta=0.1, lambda_v=1000.0)
    assert float(loss) == pytest.approx(float(m["recon"] + 1000.0 * m["jump"] + 0.1 * m["kld"]), rel=1e-5)
    y_rec, _, _ = model.apply(params, x, y, jax.random.key(0))
    assert float(m["jump"]) == pytest.approx(float(jnp.sum((x[:, -1] - y_rec[:, 0]) ** 2) / B), rel=1e-5)


def test_dlow_cvae_is_the_one_band_case_of_mojos(cvae):
    from jaxmotion.models import mojo

    model, params, x, y = cvae
    twin = mojo.MojoCVAE(dim=D, horizon=T_PRED, nz=8, nh_rnn=16, nh_mlp=(20, 12), latent="vector", residual=False)
    for a, b in zip(model.apply(params, x, y, jax.random.key(4)), twin.apply(params, x, y, jax.random.key(4))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert model.latent_shape == (8,) and dlow.sample_prior is mojo.sample_prior and dlow.decode_k is mojo.decode_k
