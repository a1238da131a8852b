"""The DCT-space diffusion predictor: shapes, the schedule, DDIM with DCT completion, the EMA, and learning."""

import functools
import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxmotion.cli import main
from jaxmotion.dct import dct, idct
from jaxmotion.models import diffusion as d

T_HIS, T_PRED, D = 5, 10, 6
T = T_HIS + T_PRED


def tiny(n_dct=8, **kw):
    return d.Denoiser(dim=D, n_dct=n_dct, latent=16, ff=32, num_layers=2, num_heads=2, dropout=0.0, **kw)


def init(model, n_dct=8):
    x = jnp.zeros((1, n_dct, D))
    p = model.init(jax.random.key(0), x, jnp.ones((1,), jnp.int32), x, jnp.ones((1,)))
    # The release zero-initialises the output layers; give them weights so the tests see a non-trivial network.
    return jax.tree.map(lambda a: a + 0.1 * jax.random.normal(jax.random.key(a.size), a.shape), p)


def windows(seed, b):
    return jnp.asarray(np.cumsum(np.random.default_rng(seed).normal(size=(b, T, D)), axis=1).astype(np.float32) * 0.1)


def test_denoiser_and_sampler_shapes_for_any_k():
    model = tiny()
    p = init(model)
    x = jnp.ones((3, 8, D))
    assert model.apply(p, x, jnp.array([1, 5, 9]), x, jnp.ones(3)).shape == (3, 8, D)
    abar = d.schedule("cosine", 100)
    for k in (1, 4):
        y = jax.jit(lambda w, key, k=k: d.sample(model, p, w, key, k, t_pred=T_PRED, abar=abar, sampling_steps=10))(
            windows(0, 3)[:, :T_HIS], jax.random.key(1))
        assert y.shape == (3, k, T_PRED, D) and bool(jnp.all(jnp.isfinite(y)))
    assert float(jnp.std(y, axis=1).mean()) > 0.0  # the K samples differ


def test_the_condition_is_dropped_exactly_where_keep_is_zero():
    model = tiny()
    p = init(model)
    x, c = jnp.ones((2, 8, D)), windows(1, 2)[:, :8]
    t = jnp.array([3, 3])
    dropped = model.apply(p, x, t, c, jnp.zeros(2))
    np.testing.assert_allclose(dropped, model.apply(p, x, t, 5.0 * c, jnp.zeros(2)), rtol=1e-6)
    assert float(jnp.abs(model.apply(p, x, t, c, jnp.ones(2)) - dropped).max()) > 1e-3


def test_cosine_schedule_properties():
    abar = np.asarray(d.schedule("cosine", 1000), np.float64)
    assert abar.shape == (1000,)
    assert np.all(np.diff(abar) < 0) and 0.999 < abar[0] < 1.0 and abar[-1] < 1e-6
    betas = d.cosine_betas(1000)
    assert betas.max() == pytest.approx(0.999) and betas.min() > 0
    # abar(t) = cos^2((t/T + s)/(1 + s) pi/2) / cos^2(s/(1 + s) pi/2) (Nichol & Dhariwal Eq. (17)), before the clip.
    f = lambda t: np.cos((t / 1000 + 0.008) / 1.008 * np.pi / 2) ** 2  # noqa: E731
    np.testing.assert_allclose(abar[499], f(500) / f(0), rtol=1e-5)
    lin = np.asarray(d.schedule("linear", 1000))
    np.testing.assert_allclose(lin[0], 1 - 1e-4, rtol=1e-6)


def test_ddim_timesteps():
    t, prev = d.ddim_timesteps(1000, 100)
    assert t[0] == 1 and t[-1] == 991 and len(t) == 100 and np.all(np.diff(t) == 10)
    np.testing.assert_array_equal(prev, np.concatenate([[0], t[:-1]]))
    assert len(d.ddim_timesteps(1000, 10)[0]) == 10 and len(d.ddim_timesteps(1000, 25)[0]) == 25
    for bad in (30, 1000):
        with pytest.raises(ValueError, match="sampling_steps"):
            d.ddim_timesteps(1000, bad)
    with pytest.raises(ValueError, match="sampling_steps"):
        d.DiffusionConfig(sampling_steps=30)
    with pytest.raises(ValueError, match="num_layers"):
        d.DiffusionConfig(num_layers=3)


def test_ddim_with_an_exact_denoiser_returns_its_x0():
    w = windows(2, 3)
    x0, abar = dct(w, T), d.schedule("cosine", 1000)
    t_seq, t_prev = d.ddim_timesteps(1000, 10)
    exact = lambda x, t: (x - jnp.sqrt(abar[t]) * x0) / jnp.sqrt(1 - abar[t])  # noqa: E731
    x_T = jax.random.normal(jax.random.key(0), x0.shape)
    out = d.ddim_sample(exact, x_T, x0, jax.random.key(1), abar=abar, t_seq=t_seq, t_prev=t_prev, t_total=T, mask=None)
    # Deterministic DDIM keeps the implied noise, and the last step lands on level abar_0 (the release's t = 0).
    eps = exact(x_T, t_seq[-1])
    np.testing.assert_allclose(out, jnp.sqrt(abar[0]) * x0 + jnp.sqrt(1 - abar[0]) * eps, atol=1e-4)
    assert float(jnp.abs(out - x0).max()) < 0.03


def test_completion_puts_the_noised_observation_in_the_masked_frames():
    # One DDIM step with the full DCT (n = T): after completion the masked frames are exactly the
    # condition noised to the previous level with the step's noise, the others the DDIM update's.
    w = windows(3, 2)
    cond = d.condition(w[:, :T_HIS], T, T)
    abar = d.schedule("cosine", 1000)
    x, key = jax.random.normal(jax.random.key(4), cond.shape), jax.random.key(5)
    eps = lambda x, t: 0.3 * x  # noqa: E731
    mask = d.completion_mask(T, D, T_HIS)
    out = d.ddim_sample(eps, x, cond, key, abar=abar, t_seq=np.array([501]), t_prev=np.array([401]), t_total=T, mask=mask)
    plain = d.ddim_sample(eps, x, cond, key, abar=abar, t_seq=np.array([501]), t_prev=np.array([401]), t_total=T, mask=None)
    a = abar[401]
    known = jnp.sqrt(a) * cond + jnp.sqrt(1 - a) * jax.random.normal(jax.random.fold_in(key, 0), cond.shape)
    np.testing.assert_allclose(idct(out, T)[:, :T_HIS], idct(known, T)[:, :T_HIS], atol=1e-5)
    np.testing.assert_allclose(idct(out, T)[:, T_HIS:], idct(plain, T)[:, T_HIS:], atol=1e-5)


def test_sampling_keeps_the_observed_part_only_with_completion():
    # Full DCT (n = T), the whole DDIM loop: the observed frames end as the observation (re-noised by
    # the last step to abar_0 ~ 1) with completion, and far from it without.
    model = tiny(n_dct=T)
    p = init(model, T)
    obs = windows(5, 4)[:, :T_HIS]
    abar = d.schedule("cosine", 1000)
    cond = d.condition(obs, T, T)
    t_seq, t_prev = d.ddim_timesteps(1000, 10)
    den = lambda x, t: model.apply(p, x, jnp.full((4,), t), cond, jnp.ones(4))  # noqa: E731
    x_T = jax.random.normal(jax.random.key(7), cond.shape)
    run = lambda mask: idct(d.ddim_sample(den, x_T, cond, jax.random.key(8), abar=abar, t_seq=t_seq,  # noqa: E731
                                          t_prev=t_prev, t_total=T, mask=mask), T)
    tol = 4 * float(jnp.sqrt(1 - abar[0]))
    assert float(jnp.abs(run(d.completion_mask(T, D, T_HIS))[:, :T_HIS] - obs).max()) < tol
    assert float(jnp.abs(run(None)[:, :T_HIS] - obs).max()) > 10 * tol
    # `sample` completes the t_his observed frames by default and nothing with complete_frames = 0.
    kw = dict(t_pred=T_PRED, abar=abar, sampling_steps=10)
    kept = d.sample(model, p, obs, jax.random.key(6), 3, **kw)
    free = d.sample(model, p, obs, jax.random.key(6), 3, complete_frames=0, **kw)
    assert kept.shape == free.shape == (4, 3, T_PRED, D) and float(jnp.abs(kept - free).max()) > 1e-3


def test_ema_weights_copy_then_average():
    tx = optax.chain(optax.sgd(1.0), d.ema_weights(0.9, start=2))
    params = {"model": {"w": jnp.array([0.0])}, "ema": {"w": jnp.array([0.0])}}
    state = tx.init(params)
    grads = {"model": {"w": jnp.array([-1.0])}, "ema": {"w": jnp.array([0.0])}}
    seen = []
    for _ in range(4):
        upd, state = tx.update(grads, state, params)
        params = optax.apply_updates(params, upd)
        seen.append((float(params["model"]["w"][0]), float(params["ema"]["w"][0])))
    # model: 1, 2, 3, 4; ema copies for 2 steps (1, 2), then 0.9 * 2 + 0.1 * 3 = 2.1, 0.9 * 2.1 + 0.1 * 4 = 2.29
    np.testing.assert_allclose(seen, [(1, 1), (2, 2), (3, 2.1), (4, 2.29)], rtol=1e-6)


def test_loss_and_its_gradient():
    model = tiny()
    p = init(model)
    loss = functools.partial(d.diffusion_loss, model, t_his=T_HIS, abar=d.schedule("cosine", 1000), cond_drop=0.0)
    (v, m), g = jax.value_and_grad(loss, has_aux=True)(p, windows(9, 16), jax.random.key(0))
    assert np.isfinite(float(v)) and float(m["cond_kept"]) == 1.0
    assert all(float(jnp.abs(x).max()) > 0 for x in jax.tree.leaves(g))


def toy_windows(rng, b):
    """Returns `(b, T, D)` sinusoids of random frequency and phase per coordinate: the past fixes the future."""
    t = np.arange(T)[None, :, None]
    w, phase = rng.uniform(0.3, 0.6, (b, 1, D)), rng.uniform(0, 2 * np.pi, (b, 1, D))
    return np.sin(w * t + phase).astype(np.float32)


@pytest.mark.slow
def test_a_small_model_learns_and_beats_zero_velocity():
    from jaxmotion.train.loop import create_state, make_train_step

    model = tiny()
    abar = d.schedule("cosine", 1000)
    x = jnp.zeros((1, 8, D))
    tx = optax.adam(1e-3)
    state = create_state(model.init(jax.random.key(0), x, jnp.ones((1,), jnp.int32), x, jnp.ones((1,))), tx)
    loss = functools.partial(d.diffusion_loss, model, t_his=T_HIS, abar=abar, cond_drop=0.2)
    step = jax.jit(make_train_step(lambda p, _f, b, k: loss(p, b, k), tx))
    rng, losses = np.random.default_rng(0), []
    for i in range(400):
        state, m = step(state, toy_windows(rng, 64), jax.random.key(i))
        losses.append(float(m["loss"]))
    assert np.mean(losses[-20:]) < 0.5 * np.mean(losses[:20])
    w = toy_windows(np.random.default_rng(1), 64)
    y = d.sample(model, state.params, w[:, :T_HIS], jax.random.key(0), 5, t_pred=T_PRED, abar=abar, sampling_steps=10)
    ade = np.linalg.norm(np.asarray(y) - w[:, None, T_HIS:], axis=-1).mean(-1).min(1).mean()
    zero_velocity = np.linalg.norm(w[:, T_HIS - 1 : T_HIS] - w[:, T_HIS:], axis=-1).mean()
    assert ade < 0.7 * zero_velocity


TINY = """
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig
def get_config():
    return Config(name="tiny_diffusion", method="diffusion", action_metrics=False, eval_k=(3,), ckpt_every=10,
                  log_every=10, max_test_windows=16, eval_batch=8,
                  method_config=DiffusionConfig(latent=16, ff=32, num_layers=2, num_heads=2, n_dct=8, num_steps=20,
                                                batch_size=8, sampling_steps=10, ema_start=5))
"""


@pytest.mark.slow
def test_the_method_trains_and_evaluates_from_the_command_line(tmp_path, capsys):
    cfg = tmp_path / "tiny.py"
    cfg.write_text(TINY)
    work = tmp_path / "work"
    assert main(["run", "--config", str(cfg), "--workdir", str(work)]) == 0
    records = json.loads((work / "metrics.json").read_text())
    assert {r["method"] for r in records} == {"diffusion", "zero_velocity"}
    for r in records:
        assert {"APD", "ADE", "FDE", "MMADE", "MMFDE"} <= set(r["metrics"]) and r["K"] == 3
    assert (work / "diffusion" / "ckpt").is_dir()
    assert main(["methods"]) == 0
    assert "diffusion" in capsys.readouterr().out
    # `jaxmotion predict` draws the run's futures from a clip, as for every method.
    from jaxmotion.data.synthetic import make_synthetic

    ds = make_synthetic(0)
    np.savez(tmp_path / "clip.npz", positions=ds.test[0].positions[:80], names=np.array(ds.skeleton.names), fps=30.0)
    assert main(["predict", str(work), "--input", str(tmp_path / "clip.npz"), "--k", "3", "--out", str(tmp_path / "pred")]) == 0
    out = np.load(tmp_path / "pred" / "futures.npz")
    assert out["futures"].shape == (3, 60, 48) and str(out["method"]) == "diffusion"
    assert np.all(np.isfinite(out["futures"])) and len(list((tmp_path / "pred").glob("future_*.bvh"))) == 3


@pytest.mark.parametrize("k,k_chunk,kw", [
    (4, None, {}),  # completion of the t_his observed frames, every sample conditioned
    (6, 3, {"cond_keep": 0.5}),  # two chunks of K; some samples unconditioned
    (4, 2, {"complete_frames": 0}),  # no completion
    (3, 1, {"complete_frames": 2, "sampling_steps": 25}),
])
def test_the_folded_sampler_equals_the_readable_one(k, k_chunk, kw):
    # `sample` (K folded into the batch, the step-invariant terms hoisted, the completion as (n, n)
    # products) against `sample_reference` (`ddim_sample` of the Flax module vmapped over K): the
    # same futures from the same key, to float32 rounding, with every layer non-zero.
    model = tiny(n_dct=6)
    p = init(model, 6)
    obs = windows(4, 3)[:, :T_HIS]
    args = dict(t_pred=T_PRED, abar=d.schedule("cosine", 1000), **{"sampling_steps": 10, **kw})
    fast = d.sample(model, p, obs, jax.random.key(9), k, k_chunk=k_chunk, **args)
    ref = d.sample_reference(model, p, obs, jax.random.key(9), k, **args)
    assert fast.shape == ref.shape == (3, k, T_PRED, D)
    np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-5 * float(jnp.abs(ref).max()))
    assert float(jnp.abs(ref).max()) > 0.1


def test_k_chunk_must_divide_k():
    model = tiny()
    with pytest.raises(ValueError, match="k_chunk"):
        d.sample(model, init(model), windows(0, 1)[:, :T_HIS], jax.random.key(0), 5, t_pred=T_PRED,
                 abar=d.schedule("cosine", 100), sampling_steps=10, k_chunk=2)


def test_k_split_over_devices_gives_the_same_futures():
    # Two forced CPU host devices need a process of their own (this one has started jax with one).
    # Each device runs its share of K (cond_keep < 1: the per-sample condition draws move with it);
    # sample k keeps its key, so the futures equal the one-device sampler's and the readable one's.
    code = textwrap.dedent("""
        import sys
        import jax, numpy as np
        sys.path.insert(0, %r)
        from test_diffusion import tiny, init, windows, T_HIS, T_PRED
        from jaxmotion.models import diffusion as d
        assert jax.device_count() == 2, jax.devices()
        model = tiny(n_dct=6)
        p = init(model, 6)
        obs = windows(4, 3)[:, :T_HIS]
        args = dict(t_pred=T_PRED, abar=d.schedule("cosine", 1000), sampling_steps=10, cond_keep=0.5)
        two = jax.jit(lambda p, o, key: d.sample(model, p, o, key, 6, devices=jax.devices(), **args))(p, obs, jax.random.key(9))
        one = d.sample(model, p, obs, jax.random.key(9), 6, **args)
        ref = d.sample_reference(model, p, obs, jax.random.key(9), 6, **args)
        assert two.shape == (3, 6, T_PRED, 6), two.shape
        tol = 1e-5 * float(np.abs(ref).max())
        np.testing.assert_allclose(two, one, rtol=1e-5, atol=tol)
        np.testing.assert_allclose(two, ref, rtol=1e-5, atol=tol)
        assert len(two.sharding.device_set) == 2, two.sharding
    """ % os.path.dirname(__file__))
    from jaxmotion.train.host_devices import host_device_env

    env = dict(host_device_env(os.environ, 2), JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]


def test_k_over_devices_must_split_evenly():
    model = tiny()
    args = dict(t_pred=T_PRED, abar=d.schedule("cosine", 100), sampling_steps=10, devices=[jax.devices()[0]] * 2)
    obs = windows(0, 1)[:, :T_HIS]
    with pytest.raises(ValueError, match=r"K \(5\) must be a multiple of the number of devices \(2\)"):
        d.sample(model, init(model), obs, jax.random.key(0), 5, **args)
    with pytest.raises(ValueError, match=r"k_chunk \(2\) must divide each device's share of K \(6 / 2 devices = 3\)"):
        d.sample(model, init(model), obs, jax.random.key(0), 6, k_chunk=2, **args)


def test_test_cond_keep_draws_conditioned_and_unconditioned_samples():
    # cond_keep = 0: every sample denoised without its condition, i.e. as a model whose condition
    # embedding is zero; cond_keep = 1 (default): all conditioned; in between, some of each.
    model = tiny()
    p = init(model)
    no_cond = jax.tree_util.tree_map_with_path(
        lambda path, a: jnp.zeros_like(a) if "cond_embed" in jax.tree_util.keystr(path) else a, p)
    obs, abar = windows(3, 2)[:, :T_HIS], d.schedule("cosine", 100)
    run = lambda params, **kw: d.sample(model, params, obs, jax.random.key(4), 6, t_pred=T_PRED, abar=abar,  # noqa: E731
                                        sampling_steps=10, **kw)
    with_cond, without = run(p), run(no_cond)
    assert float(jnp.abs(with_cond - without).max()) > 1e-3
    np.testing.assert_allclose(run(p, cond_keep=0.0), without, atol=1e-5)
    half = run(p, cond_keep=0.5)
    dist = lambda a: jnp.abs(half - a).max(axis=(0, 2, 3))  # noqa: E731  per sample k
    conditioned = np.asarray(dist(with_cond) < 1e-5)
    unconditioned = np.asarray(dist(without) < 1e-5)
    assert np.all(conditioned ^ unconditioned) and conditioned.any() and unconditioned.any()


def test_lr_milestones_give_the_release_step_decay():
    from jaxmotion.methods.diffusion import learning_rate

    step = learning_rate(d.DiffusionConfig(lr=1e-3, num_steps=1000, lr_milestones=(0.15, 0.3), lr_gamma=0.9))
    assert [float(step(s)) for s in (0, 149, 150, 299, 300, 999)] == pytest.approx(
        [1e-3, 1e-3, 9e-4, 9e-4, 8.1e-4, 8.1e-4])
    linear = learning_rate(d.DiffusionConfig(lr=1e-3, num_steps=1000, lr_fix_fraction=0.5))
    assert float(linear(999)) < 1e-5
    with pytest.raises(ValueError, match="lr_milestones"):
        d.DiffusionConfig(lr_milestones=(0.5, 0.2))
    with pytest.raises(ValueError, match="test_cond_keep"):
        d.DiffusionConfig(test_cond_keep=1.5)
