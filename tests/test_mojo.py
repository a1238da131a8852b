"""MOJO: robust KLD, the latent DCT CVAE, the public decoder step, per-band DLow and the method end to end."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion import losses
from jaxmotion.cli import main
from jaxmotion.dct import dct_matrix
from jaxmotion.models import mojo

D, T_HIS, T_PRED, B, NZ, K = 6, 4, 10, 3, 4, 5


def _arr(seed, shape, scale=1.0):
    return jnp.asarray(scale * np.random.default_rng(seed).normal(size=shape), jnp.float32)


def _setup(latent):
    cfg = mojo.MojoConfig(latent=latent, nz=NZ, nh_rnn=16, nh_mlp=(20, 12), q_nh_rnn=8, q_nh_mlp=(16,))
    model = mojo.cvae_model(cfg, D, T_PRED)
    x, y = _arr(0, (B, T_HIS, D)), _arr(1, (B, T_PRED, D))
    # Jitted where the property is not about jit: compiling once is faster than op-by-op scans.
    params = jax.jit(model.init)(jax.random.key(0), x, y, jax.random.key(1))
    q = mojo.q_model(cfg, T_PRED, K)
    q_params = jax.jit(q.init)(jax.random.key(2), x, jnp.zeros((x.shape[0], q.n_low, NZ)))
    return cfg, model, params, q, q_params, x, y


@pytest.fixture(scope="module", params=["dct", "vector"])
def setup(request):
    """Both latent spaces: for the structural properties."""
    return _setup(request.param)


@pytest.fixture(scope="module")
def dct_setup():
    """The DCT latent only: for the slower properties (one compile instead of two)."""
    return _setup("dct")


# ---------------------------------------------------------------------------------------------
# Robust KLD and KL divergences.


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1e4, allow_nan=False))
def test_robust_kld_is_nonnegative_and_below_identity(s):
    psi = float(losses.robust_kld(jnp.float32(s)))
    assert psi >= 0.0
    assert psi <= s * (1 + 1e-6) + 1e-6


def test_robust_kld_is_half_square_near_zero_and_linear_far_away():
    s = jnp.asarray([1e-3, 1e-2, 5e-2], jnp.float32)
    np.testing.assert_allclose(np.asarray(losses.robust_kld(s)), np.asarray(s**2 / 2), rtol=1e-3)
    assert float(losses.robust_kld(jnp.float32(-3.0))) >= 0.0
    # Far from 0 it grows like |s| - 1: a large KLD is penalised linearly, not quadratically.
    np.testing.assert_allclose(float(losses.robust_kld(jnp.float32(1000.0))), 999.0005, rtol=1e-5)


def test_kld_of_identical_gaussians_is_zero():
    z = jnp.zeros((3, NZ))
    assert float(jnp.max(jnp.abs(losses.kld_normal(z, z)))) == 0.0  # N(0, I) vs N(0, I)
    assert float(jnp.max(jnp.abs(losses.kld_affine(jnp.ones((3, NZ)), z)))) == 0.0
    # Positive otherwise: KL(N(1, e) || N(0, 1)) = 0.5 (e + 1 - 1 - 1) per dim.
    np.testing.assert_allclose(float(losses.kld_normal(jnp.ones(1), jnp.ones(1))), 0.5 * (np.e + 1 - 2), rtol=1e-6)


def test_cvae_loss_is_eq1_with_element_means(dct_setup):
    cfg, model, params, *_, x, y = dct_setup
    batch = jnp.concatenate([x, y], axis=1)
    key = jax.random.key(5)
    loss, m = jax.jit(lambda p, b, k: mojo.cvae_loss(model, p, b, k, t_his=T_HIS, **mojo.cvae_loss_weights(cfg)))(params, batch, key)
    y_rec, mu, logvar = jax.jit(model.apply)(params, x, y, key)
    recon = np.mean(np.abs(np.asarray(y_rec - y)))
    vel = np.mean(np.abs(np.diff(np.asarray(y_rec), axis=1) - np.diff(np.asarray(y), axis=1)))
    kld = 0.5 * np.mean(-1 - np.asarray(logvar) + np.asarray(mu) ** 2 + np.exp(np.asarray(logvar)))
    np.testing.assert_allclose(float(m["kld"]), kld, rtol=1e-5)
    np.testing.assert_allclose(float(loss), recon + 3.0 * vel + (np.sqrt(1 + kld**2) - 1), rtol=1e-5)


# ---------------------------------------------------------------------------------------------
# The latent DCT space.


def test_latent_has_a_gaussian_per_dct_band(setup):
    cfg, model, params, *_, x, y = setup
    mu, logvar = model.apply(params, x, y, method=mojo.MojoCVAE.encode)
    bands = T_PRED if cfg.latent == "dct" else 1
    assert mu.shape == logvar.shape == ((B, bands, NZ) if cfg.latent == "dct" else (B, NZ))
    z = _arr(3, (B,) + model.latent_shape)
    z_t = model.apply(params, z, method=mojo.MojoCVAE.latent_to_time)
    ref = np.einsum("ct,bcz->btz", np.asarray(dct_matrix(T_PRED)), np.asarray(z)) if bands > 1 else np.repeat(np.asarray(z)[:, None], T_PRED, 1)
    np.testing.assert_allclose(np.asarray(z_t), ref, atol=1e-5)


@pytest.mark.slow
def test_encoder_bands_are_the_dct_of_per_frame_states():
    # A constant future makes the per-frame encoder input constant only in the DCT's band 0 if
    # the encoder GRU state were constant; instead check linearity: the band features equal the
    # DCT of the per-frame features computed by hand.
    cfg = mojo.MojoConfig(nz=NZ, nh_rnn=8, nh_mlp=(8,))
    model = mojo.cvae_model(cfg, D, T_PRED)
    x, y = _arr(0, (1, T_HIS, D)), _arr(1, (1, T_PRED, D))
    params = jax.jit(model.init)(jax.random.key(0), x, y)
    mu, _ = jax.jit(lambda p: model.apply(p, x, y, method=mojo.MojoCVAE.encode))(params)

    def by_hand(m):
        h_x = m.encode_x(x)
        h_y = m.e_rnn(y)
        h = jnp.concatenate([jnp.repeat(h_x[:, None], T_PRED, 1), h_y], -1)
        h = jnp.einsum("ct,btd->bcd", dct_matrix(T_PRED), h)
        return m.e_mu(m.e_mlp(h))

    np.testing.assert_allclose(np.asarray(mu), np.asarray(jax.jit(lambda p: model.apply(p, method=by_hand))(params)), atol=1e-5)


def test_low_band_count_is_the_lowest_fifth():
    assert mojo.num_low_bands(mojo.MojoConfig(), 45) == 9  # the release's n_freq for t_pred = 45
    assert mojo.num_low_bands(mojo.MojoConfig(), 60) == 12
    assert mojo.num_low_bands(mojo.MojoConfig(latent="vector"), 60) == 1


def test_bad_config_is_rejected_with_the_field_name():
    with pytest.raises(ValueError, match="latent"):
        mojo.MojoConfig(latent="fft")
    with pytest.raises(ValueError, match="baselines"):
        mojo.MojoConfig(baselines=("dlow",))
    with pytest.raises(ValueError, match="q_recon"):
        mojo.MojoConfig(q_recon="l2")


def test_q_reconstruction_norm_follows_the_objectives_release_unless_named():
    # MOJO's release (train_MOJO_dlow.py) sums absolute errors, DLow's squared ones.
    norm = lambda **kw: mojo.q_loss_weights(mojo.MojoConfig(**kw))["recon_norm"]  # noqa: E731
    assert (norm(), norm(loss="dlow")) == ("l1", "sq")
    assert (norm(q_recon="sq"), norm(loss="dlow", q_recon="l1")) == ("sq", "l1")


# ---------------------------------------------------------------------------------------------
# The public decoder step.


def test_decode_step_in_lax_scan_equals_the_full_decoder(setup):
    cfg, model, params, *_, x, _ = setup
    z = _arr(4, (B,) + model.latent_shape)
    full = model.apply(params, x, z, method=mojo.MojoCVAE.decode)
    dp = mojo.decoder_params(model, params)
    carry, inputs = mojo.decode_inputs(dp, x, z)
    assert jax.tree.map(lambda a: a.shape[0], inputs) == mojo.DecodeInputs(T_PRED, T_PRED)
    _, frames = jax.jit(lambda p, c, i: jax.lax.scan(lambda cc, ii: mojo.decode_step(p, cc, ii), c, i))(dp, carry, inputs)
    np.testing.assert_allclose(np.asarray(jnp.swapaxes(frames, 0, 1)), np.asarray(full), atol=1e-5)


def test_decode_step_continues_from_a_replaced_frame(dct_setup):
    # Recursive projection replaces each predicted frame; with residual output the next frame is
    # the replaced frame plus the predicted change.
    cfg, model, params, *_, x, _ = dct_setup
    dp = mojo.decoder_params(model, params)
    carry, inputs = mojo.decode_inputs(dp, x, _arr(4, (B,) + model.latent_shape))
    step0 = jax.tree.map(lambda a: a[0], inputs)
    c1, _ = mojo.decode_step(dp, carry, step0)
    fitted = _arr(6, (B, D))
    step1 = jax.tree.map(lambda a: a[1], inputs)
    c_a, y_a = mojo.decode_step(dp, c1._replace(y_prev=fitted), step1)
    c_b, y_b = mojo.decode_step(dp, c1._replace(y_prev=fitted + 1.0), step1)
    assert cfg.residual
    assert not np.allclose(np.asarray(y_a), np.asarray(y_b))
    np.testing.assert_allclose(np.asarray(c_a.y_prev), np.asarray(y_a))


@pytest.mark.slow
def test_no_residual_decoder_outputs_the_head_directly():
    cfg = mojo.MojoConfig(residual=False, nz=NZ, nh_rnn=8, nh_mlp=(8,))
    model = mojo.cvae_model(cfg, D, T_PRED)
    x, y = _arr(0, (2, T_HIS, D)), _arr(1, (2, T_PRED, D))
    params = jax.jit(model.init)(jax.random.key(0), x, y)
    dp = mojo.decoder_params(model, params)
    carry, inputs = mojo.decode_inputs(dp, x, jnp.zeros((2, T_PRED, NZ)))
    i0 = jax.tree.map(lambda a: a[0], inputs)
    _, ya = mojo.decode_step(dp, carry, i0)
    h = model.apply(params, carry.h, jnp.concatenate([i0.h_x, i0.z_t, carry.y_prev], -1), method=lambda m, h, u: m.d_cell(h, u))
    ref = model.apply(params, h, method=lambda m, h: m.d_out(m.d_mlp(h)))
    np.testing.assert_allclose(np.asarray(ya), np.asarray(ref), atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Sampling.


def test_k_samples_by_vmap_equal_a_loop_over_k(setup):
    cfg, model, params, *_, x, _ = setup
    z = _arr(7, (B, K) + model.latent_shape)
    ys = jax.jit(lambda p, x, z: mojo.decode_k(model, p, x, z))(params, x, z)
    assert ys.shape == (B, K, T_PRED, D)
    decode = jax.jit(lambda p, x, z: model.apply(p, x, z, method=mojo.MojoCVAE.decode))
    for k in range(K):
        yk = decode(params, x, z[:, k])
        np.testing.assert_allclose(np.asarray(ys[:, k]), np.asarray(yk), atol=1e-5)


@pytest.mark.slow
def test_jit_and_no_jit_samplers_agree(dct_setup):
    cfg, model, params, q, q_params, x, _ = dct_setup
    key = jax.random.key(9)
    fn = lambda x, key: mojo.sample_mojo(model, params, q, q_params, x, key)
    np.testing.assert_allclose(np.asarray(jax.jit(fn)(x, key)), np.asarray(fn(x, key)), atol=1e-5)
    pr = lambda x, key: mojo.sample_prior(model, params, x, key, K)
    np.testing.assert_allclose(np.asarray(jax.jit(pr)(x, key)), np.asarray(pr(x, key)), atol=1e-5)


@pytest.mark.slow
def test_dlow_drives_only_the_lowest_bands(dct_setup):
    cfg, model, params, q, q_params, x, _ = dct_setup
    key = jax.random.key(3)
    z, a, b = jax.jit(lambda qp: mojo.q_latents(model, q, qp, x, key))(q_params)
    L = q.n_low
    assert z.shape == (B, K) + model.latent_shape and a.shape == (B, L, K, NZ)
    # Low bands: one noise draw per window and band, mapped by K affine maps (DLow Eq. (4)).
    eps = (z[:, :, :L] - jnp.swapaxes(b, 1, 2)) / jnp.exp(0.5 * jnp.swapaxes(a, 1, 2))
    np.testing.assert_allclose(np.asarray(eps), np.asarray(jnp.broadcast_to(eps[:, :1], eps.shape)), atol=1e-4)
    # High bands: independent N(0, I) per sample, so they differ across k.
    if model.n_bands > L:
        assert float(jnp.std(z[:, :, L:], axis=1).mean()) > 0.3
    # The sampler decodes exactly these latents.
    ys = jax.jit(lambda p, qp: mojo.sample_mojo(model, p, q, qp, x, key))(params, q_params)
    ref = jax.jit(lambda p: mojo.decode_k(model, p, x, z))(params)
    np.testing.assert_allclose(np.asarray(ys), np.asarray(ref), atol=1e-5)


@pytest.mark.slow
def test_unshared_band_networks_have_one_network_per_band():
    cfg = mojo.MojoConfig(nz=NZ, q_shared_trunk=False, q_nh_rnn=8, q_nh_mlp=(16,))
    q = mojo.q_model(cfg, T_PRED, K)
    x = _arr(0, (2, T_HIS, D))
    p = jax.jit(q.init)(jax.random.key(0), x, jnp.zeros((x.shape[0], q.n_low, NZ)))
    leaves = jax.tree.leaves(p)
    assert all(leaf.shape[0] == q.n_low for leaf in leaves)
    z, a, b = q.apply(p, x, _arr(1, (2, q.n_low, NZ)))
    assert z.shape == (2, K, q.n_low, NZ)


@pytest.mark.slow
def test_q_loss_has_dlow_terms_and_gradients_only_for_q(dct_setup):
    cfg, model, params, q, q_params, x, y = dct_setup
    batch = jnp.concatenate([x, y], axis=1)
    (loss, m), grads = jax.jit(jax.value_and_grad(
        lambda qp, cp: mojo.q_loss(q, qp, model, cp, batch, jax.random.key(0), t_his=T_HIS, **mojo.q_loss_weights(cfg)), argnums=(0, 1), has_aux=True
    ))(q_params, params)
    assert np.isfinite(float(loss)) and 0.0 < float(m["div"]) <= 1.0
    np.testing.assert_allclose(float(loss), float(m["kld"] + 25.0 * m["div"] + 2.0 * m["recon"]), rtol=1e-5)
    assert max(float(jnp.max(jnp.abs(g))) for g in jax.tree.leaves(grads[1])) == 0.0
    assert max(float(jnp.max(jnp.abs(g))) for g in jax.tree.leaves(grads[0])) > 0.0


# ---------------------------------------------------------------------------------------------
# The method end to end on the synthetic data, tiny budget.

TINY = """
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig
def get_config():
    return Config(name="tiny_mojo", action_metrics=False, method="mojo", eval_k=(4,), ckpt_every=5, log_every=5,
                  max_test_windows=24, eval_batch=12,
                  method_config=MojoConfig(nz=4, nh_rnn=16, nh_mlp=(16,), num_steps=10, batch_size=8,
                                  q_nh_rnn=8, q_nh_mlp=(16,), q_num_steps=5, q_batch_size=4,
                                  baselines=("zero_velocity",)))
"""


@pytest.mark.slow
def test_mojo_method_trains_resumes_and_reports_realism(tmp_path):
    cfg = tmp_path / "tiny_mojo.py"
    cfg.write_text(TINY)
    work = tmp_path / "work"
    assert main(["run", "--config", str(cfg), "--workdir", str(work)]) == 0
    records = json.loads((work / "metrics.json").read_text())
    assert {r["method"] for r in records} == {"mojo", "zero_velocity"}
    for r in records:
        assert {"APD", "ADE", "FDE", "MMADE", "MMFDE", "FSE", "BDF"} <= set(r["metrics"])
    zv = next(r for r in records if r["method"] == "zero_velocity")["metrics"]
    assert zv["BDF"] == pytest.approx(0.0, abs=1e-5) and zv["APD"] == 0.0
    assert (work / "cvae" / "ckpt").is_dir() and (work / "q_k4" / "ckpt").is_dir()
    with pytest.raises(FileExistsError, match="--resume"):
        main(["train", "--config", str(cfg), "--workdir", str(work)])
    # Resuming a finished run trains nothing and leaves every stage's parameters as they were.
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    c = load_config(cfg)
    prep = experiment.prepare(experiment.load_data(c), c.max_test_windows)
    before = experiment.restore(c, prep, work)
    logs = {s: (work / s / "log.jsonl").read_text() for s in ("cvae", "q_k4")}
    assert main(["train", "--config", str(cfg), "--workdir", str(work), "--resume"]) == 0
    after = experiment.restore(c, prep, work)
    assert sorted(before) == sorted(after) == ["cvae", "q_k4"]
    for a, b in zip(jax.tree.leaves(before), jax.tree.leaves(after)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert logs == {s: (work / s / "log.jsonl").read_text() for s in ("cvae", "q_k4")}


def test_q_num_steps_zero_trains_the_cvae_alone(tmp_path):
    # MOJO's VAE+DCT row: no Q stage; the CVAE is sampled from N(0, I) in every band ("mojo_prior").
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    with pytest.raises(ValueError, match="mojo_prior"):
        mojo.MojoConfig(q_num_steps=0, baselines=("zero_velocity",))
    with pytest.raises(ValueError, match="q_num_steps"):
        mojo.MojoConfig(q_num_steps=-1)
    cfg = tmp_path / "tiny_vae_dct.py"
    cfg.write_text(TINY.replace("q_num_steps=5", "q_num_steps=0").replace('("zero_velocity",)', '("mojo_prior",)'))
    c = load_config(cfg)
    prep = experiment.prepare(experiment.load_data(c), c.max_test_windows)
    from jaxmotion.methods import mojo as mojo_method

    assert [s.name for s in mojo_method.stages(c, prep)] == ["cvae"]
    base = load_config(_write(tmp_path / "tiny.py", TINY))
    assert [s.name for s in mojo_method.stages(base, prep)] == ["cvae", "q_k4"]


def _write(path, text):
    path.write_text(text)
    return path
