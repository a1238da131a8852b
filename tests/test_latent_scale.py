"""experiments/latent_scale.py: its sampler at s = 1 is the library's CVAE sampler, and s scales the draws it decodes."""

import importlib.util
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.models import dlow
from jaxmotion.models.cvae import decode_k

ROOT = Path(__file__).resolve().parents[1]
D, T_HIS, T_PRED, B, K = 6, 4, 5, 3, 7


def _module():
    spec = importlib.util.spec_from_file_location("latent_scale", ROOT / "experiments" / "latent_scale.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_scaled_prior_is_the_cvae_sampler_at_one_and_decodes_scaled_draws():
    ls = _module()
    model = dlow.DLowCVAE(dim=D, horizon=T_PRED, nz=8, nh_rnn=16, nh_mlp=(20, 12))
    x = jnp.asarray(np.random.default_rng(0).normal(size=(B, T_HIS, D)), jnp.float32)
    params = model.init(jax.random.key(0), x, jnp.zeros((B, T_PRED, D)), jax.random.key(1))
    key = jax.random.key(5)
    want = dlow.sample_prior(model, params, x, key, K)
    np.testing.assert_allclose(np.asarray(ls.scaled_prior(model, params, K, 1.0)(x, key)), np.asarray(want), rtol=1e-6, atol=1e-6)
    z = jax.random.normal(key, (B, K, 8))
    half = ls.scaled_prior(model, params, K, 0.5)(x, key)
    np.testing.assert_allclose(np.asarray(half), np.asarray(decode_k(model, params, x, 0.5 * z)), rtol=1e-5, atol=1e-6)
    assert not np.allclose(np.asarray(half), np.asarray(want))


def test_scaled_q_is_mojos_sampler_at_one_and_spreads_only_the_low_bands_about_their_mean():
    from jaxmotion.models import mojo

    ls = _module()
    cfg = mojo.MojoConfig(nz=4, nh_rnn=8, nh_mlp=(8,), q_nh_rnn=8, q_nh_mlp=(8,), dlow_band_fraction=0.4)
    model = mojo.cvae_model(cfg, D, T_PRED)
    x = jnp.asarray(np.random.default_rng(0).normal(size=(B, T_HIS, D)), jnp.float32)
    params = jax.jit(model.init)(jax.random.key(0), x, jnp.zeros((B, T_PRED, D)), jax.random.key(1))
    q = mojo.q_model(cfg, T_PRED, K)
    assert 0 < q.n_low < model.n_bands  # low bands from Q, the bands above from N(0, I)
    q_params = jax.jit(q.init)(jax.random.key(2), x, jnp.zeros((B, q.n_low, 4)))
    key = jax.random.key(5)
    want = mojo.sample_mojo(model, params, q, q_params, x, key)
    np.testing.assert_allclose(np.asarray(ls.scaled_q(model, params, q, q_params, 1.0)(x, key)), np.asarray(want),
                               rtol=1e-5, atol=1e-6)
    z, _, _ = mojo.q_latents(model, q, q_params, x, key)
    z = np.asarray(z)
    spread = z.copy()
    mean = z[:, :, : q.n_low].mean(axis=1, keepdims=True)
    spread[:, :, : q.n_low] = mean + 2.0 * (z[:, :, : q.n_low] - mean)
    got = ls.scaled_q(model, params, q, q_params, 2.0)(x, key)
    np.testing.assert_allclose(np.asarray(got), np.asarray(decode_k(model, params, x, jnp.asarray(spread))), rtol=1e-5, atol=1e-5)
    assert not np.allclose(np.asarray(got), np.asarray(want))
