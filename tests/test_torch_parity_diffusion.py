"""jaxmotion's diffusion predictor and its PyTorch twin (benchmarks/torch_ref/diffusion.py) compute the same futures.

Same weights (converted from jaxmotion), same windows, same noise (the start x_T and the completion's
noise of every step) -> the denoiser's outputs and the sampled futures agree to float32 tolerance,
with the JAX sampler's lax.scan over steps (the K samples in the batch) against the release's Python loop over
steps with the K samples in the batch. Skipped when PyTorch is not installed.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install -e '.[bench]')")
pytestmark = pytest.mark.slow
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repo root, for `benchmarks`

from benchmarks.torch_ref import convert  # noqa: E402
from benchmarks.torch_ref import diffusion as tdiff  # noqa: E402
from jaxmotion.models import diffusion  # noqa: E402

D, T_HIS, T_PRED, B, K, N = 6, 5, 10, 3, 4, 8
SIZES = dict(latent=16, ff=24, num_layers=4, num_heads=2)


def rel_close(a, b, rel=1e-4):
    a, b = np.asarray(a, np.float64), np.asarray(b.detach().numpy() if hasattr(b, "detach") else b, np.float64)
    assert a.shape == b.shape
    assert np.linalg.norm(a - b) <= rel * np.linalg.norm(b), np.linalg.norm(a - b) / np.linalg.norm(b)
    np.testing.assert_allclose(a, b, rtol=rel, atol=rel * np.max(np.abs(b)))


@pytest.fixture(scope="module")
def pair():
    jm = diffusion.Denoiser(dim=D, n_dct=N, dropout=0.0, **SIZES)
    x = jnp.zeros((1, N, D))
    p = jm.init(jax.random.key(0), x, jnp.ones((1,), jnp.int32), x, jnp.ones((1,)))
    # The zero-initialised layers get weights, so every layer shows in the output.
    p = jax.tree.map(lambda a: a + 0.2 * jax.random.normal(jax.random.key(a.size + a.ndim), a.shape), p)
    tm = convert.diffusion_denoiser(tdiff.Denoiser(D, N, dropout=0.0, **SIZES), p).eval()
    w = np.cumsum(np.random.default_rng(0).normal(size=(B, T_HIS + T_PRED, D)), axis=1).astype(np.float32) * 0.1
    return jm, p, tm, w


def test_parameter_counts_match(pair):
    jm, p, tm, _ = pair
    assert sum(int(np.size(v)) for v in jax.tree.leaves(p)) == sum(q.numel() for q in tm.parameters())


def test_denoiser_matches_with_and_without_the_condition(pair):
    jm, p, tm, w = pair
    rng = np.random.default_rng(1)
    x, c = rng.normal(size=(B, N, D)).astype(np.float32), rng.normal(size=(B, N, D)).astype(np.float32)
    t = np.array([1, 500, 999])
    with torch.no_grad():
        rel_close(jm.apply(p, x, t, c, jnp.ones(B)), tm(torch.tensor(x), torch.tensor(t), torch.tensor(c)))
        rel_close(jm.apply(p, x, t, c, jnp.zeros(B)), tm(torch.tensor(x), torch.tensor(t), None))


@pytest.mark.parametrize("steps,complete", [(10, True), (25, True), (10, False)])
def test_sampled_futures_match(pair, steps, complete):
    jm, p, tm, w = pair
    abar = diffusion.schedule("cosine", 1000)
    key = jax.random.key(3)
    obs = w[:, :T_HIS]
    y = diffusion.sample(jm, p, obs, key, K, t_pred=T_PRED, abar=abar, sampling_steps=steps,
                         complete_frames=None if complete else 0)
    # `diffusion.sample`'s draws: sample j starts from normal(split(key_j)[0]) and completes step i with
    # normal(fold_in(split(key_j)[1], i)); PyTorch's batch holds sample j of window w at row w * K + j.
    pairs = [jax.random.split(kj) for kj in jax.random.split(key, K)]
    shape = (B, N, D)
    rows = lambda a: torch.tensor(np.asarray(jnp.stack(a, axis=1).reshape(B * K, N, D)))  # noqa: E731
    x_T = rows([jax.random.normal(k0, shape) for k0, _ in pairs])
    step_noise = lambda i: rows([jax.random.normal(jax.random.fold_in(k1, i), shape) for _, k1 in pairs])  # noqa: E731
    t_seq, t_prev = diffusion.ddim_timesteps(1000, steps)
    mask = torch.tensor(np.asarray(diffusion.completion_mask(T_HIS + T_PRED, D, T_HIS))) if complete else None
    with torch.no_grad():
        ty = tdiff.sample_ddim(tm, torch.tensor(obs), K, t_pred=T_PRED, n_dct=N, abar=torch.tensor(np.asarray(abar)),
                               t_seq=t_seq, t_prev=t_prev, mask=mask, x_T=x_T, step_noise=step_noise)
    assert y.shape == tuple(ty.shape) == (B, K, T_PRED, D)
    rel_close(y, ty, rel=2e-4)


def test_the_twins_schedule_and_the_benchmarks_sizes_are_jaxmotions():
    from benchmarks.harness import DIFFUSION_NOISE_STEPS, DIFFUSION_SIZES

    for steps in (10, 100):
        abar, t_seq, t_prev = tdiff.ddim_schedule(1000, steps)
        np.testing.assert_allclose(abar.numpy(), np.asarray(diffusion.schedule("cosine", 1000)), rtol=1e-6)
        for a, b in zip((t_seq, t_prev), diffusion.ddim_timesteps(1000, steps)):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(tdiff.completion_mask(15, 6, 5).numpy(), np.asarray(diffusion.completion_mask(15, 6, 5)))
    c = diffusion.DiffusionConfig()
    assert DIFFUSION_SIZES == {k: getattr(c, k) for k in DIFFUSION_SIZES} and DIFFUSION_NOISE_STEPS == c.noise_steps
