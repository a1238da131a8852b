"""jaxmotion and the PyTorch reference models (benchmarks/torch_ref) compute the same functions.

Same weights (converted from jaxmotion), same inputs, same noise -> outputs agree to a relative
error of 1e-4 in float32 (||a - b|| / ||b||, and elementwise within 1e-4 of the output's scale),
and the two twins have the same parameter counts. Skipped when PyTorch is not installed.
"""

import copy
import functools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install -e '.[bench]')")
pytestmark = pytest.mark.slow  # imports torch and builds every model twice
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repo root, for `benchmarks`

from benchmarks.torch_ref import convert  # noqa: E402
from benchmarks.torch_ref import dlow as tdlow  # noqa: E402
from jaxmotion.models import dlow  # noqa: E402

D, T_HIS, T_PRED, B, NZ, K = 6, 4, 7, 3, 8, 5
REL = 1e-4


def rel_close(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b.detach().numpy() if hasattr(b, "detach") else b, np.float64)
    assert a.shape == b.shape
    scale = np.linalg.norm(b)
    assert np.linalg.norm(a - b) <= REL * scale, np.linalg.norm(a - b) / scale
    np.testing.assert_allclose(a, b, rtol=REL, atol=REL * np.max(np.abs(b)))


def n_params(tree) -> int:
    return sum(int(np.size(v)) for v in jax.tree.leaves(tree))


def n_torch(module) -> int:
    return sum(p.numel() for p in module.parameters())


def tt(a):
    return torch.tensor(np.asarray(a))


def data(seed, *shape):
    return np.random.default_rng(seed).normal(size=shape).astype(np.float32)


@pytest.fixture(scope="module")
def dlow_pair():
    jm = dlow.DLowCVAE(dim=D, horizon=T_PRED, nz=NZ, nh_rnn=16, nh_mlp=(20, 12))
    x, y = data(0, B, T_HIS, D), data(1, B, T_PRED, D)
    p = jax.jit(jm.init)(jax.random.key(0), x, y, jax.random.key(1))
    jq = dlow.DLowQ(nz=NZ, nk=K, nh_rnn=16, nh_mlp=(32, 24))
    qp = jax.jit(jq.init)(jax.random.key(2), x, jnp.zeros((B, NZ)))
    tm = convert.dlow_cvae(tdlow.DLowCVAE(D, T_PRED, nz=NZ, nh_rnn=16, nh_mlp=(20, 12)), p)
    tq = convert.dlow_q(tdlow.DLowQ(D, nz=NZ, nk=K, nh_rnn=16, nh_mlp=(32, 24)), qp)
    return jm, p, jq, qp, tm, tq, x, y


def test_dlow_parameter_counts_match(dlow_pair):
    jm, p, jq, qp, tm, tq, *_ = dlow_pair
    assert n_params(p) == n_torch(tm)
    assert n_params(qp) == n_torch(tq)
    # At the benchmark's (published) sizes too: nothing is skipped by the small test sizes.
    big = dlow.DLowCVAE(dim=60, horizon=3)
    shapes = jax.eval_shape(lambda: big.init(jax.random.key(0), jnp.zeros((1, 15, 60)), jnp.zeros((1, 3, 60))))
    assert n_params(shapes) == n_torch(tdlow.DLowCVAE(60, 3)) == 741_528
    qshapes = jax.eval_shape(lambda: dlow.DLowQ().init(jax.random.key(0), jnp.zeros((1, 15, 60)), jnp.zeros((1, 128))))
    assert n_params(qshapes) == n_torch(tdlow.DLowQ(60))


def test_dlow_cvae_reconstruction_and_loss_match(dlow_pair):
    jm, p, *_, tm, _, x, y = dlow_pair
    key = jax.random.key(7)
    # jaxmotion draws z = mu + std * normal(key); give PyTorch the same normal draw.
    eps = np.asarray(jax.random.normal(key, (B, NZ)))
    jy, jmu, jlv = jm.apply(p, x, y, key)
    with torch.no_grad():
        ty, tmu, tlv = tm(tt(x), tt(y), tt(eps))
    rel_close(jmu, tmu)
    rel_close(jlv, tlv)
    rel_close(jy, ty)
    batch = np.concatenate([x, y], axis=1)
    jl, jmet = dlow.cvae_loss(jm, p, batch, key, t_his=T_HIS, beta=0.1, lambda_v=1000.0)
    with torch.no_grad():
        tl, tmet = tdlow.cvae_loss(tm, tt(batch), tt(eps), t_his=T_HIS, beta=0.1, lambda_v=1000.0)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])


def test_dlow_cvae_loss_gradients_match(dlow_pair):
    jm, p, *_, tm, _, x, y = dlow_pair
    key = jax.random.key(3)
    eps = np.asarray(jax.random.normal(key, (B, NZ)))
    batch = np.concatenate([x, y], axis=1)
    g = jax.jit(jax.grad(lambda p: dlow.cvae_loss(jm, p, batch, key, t_his=T_HIS, beta=0.1, lambda_v=1000.0)[0]))(p)
    tm.zero_grad()
    tdlow.cvae_loss(tm, tt(batch), tt(eps), t_his=T_HIS, beta=0.1, lambda_v=1000.0)[0].backward()
    # The gradients, read back through the same conversion as the weights, are the same numbers.
    gt = convert.dlow_cvae(tdlow.DLowCVAE(D, T_PRED, nz=NZ, nh_rnn=16, nh_mlp=(20, 12)), g)
    named, grads = list(tm.named_parameters()), list(gt.parameters())
    assert len(named) == len(grads) > 0
    for (name, a), b in zip(named, grads):
        rel_close(b.detach().numpy(), a.grad)


def test_dlow_decoding_and_prior_sampling_match(dlow_pair):
    jm, p, *_, tm, _, x, _ = dlow_pair
    z = data(4, B, K, NZ)
    jys = dlow.decode_k(jm, p, x, z)
    with torch.no_grad():
        tys = tdlow.decode_k(tm, tt(x), tt(z))
    assert jys.shape == (B, K, T_PRED, D)
    rel_close(jys, tys)


def test_dlow_q_sampling_and_loss_match(dlow_pair):
    jm, p, jq, qp, tm, tq, x, y = dlow_pair
    key = jax.random.key(5)
    eps = np.asarray(jax.random.normal(key, (B, NZ)))  # what sample_dlow / dlow_loss draw from `key`
    jz, ja, jb = jq.apply(qp, x, eps)
    with torch.no_grad():
        tz, ta, tb = tq(tt(x), tt(eps))
        tys = tdlow.sample_dlow(tm, tq, tt(x), tt(eps))
    rel_close(jz, tz)
    rel_close(ja, ta)
    rel_close(jb, tb)
    rel_close(dlow.sample_dlow(jm, p, jq, qp, x, key), tys)
    batch = np.concatenate([x, y], axis=1)
    kw = dict(t_his=T_HIS, d_scale=100.0, lambda_j=25.0, lambda_recon=2.0, lambda_kl=1.0)
    jl, jmet = dlow.dlow_loss(jq, qp, jm, p, batch, key, **kw)
    with torch.no_grad():
        tl, tmet = tdlow.dlow_loss(tq, tm, tt(batch), tt(eps), **kw)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])


def test_conversion_rejects_mismatched_sizes(dlow_pair):
    _, p, *_ = dlow_pair
    with pytest.raises(ValueError, match="x_rnn"):
        convert.dlow_cvae(tdlow.DLowCVAE(D + 1, T_PRED, nz=NZ, nh_rnn=16, nh_mlp=(20, 12)), p)


# ---------------------------------------------------------------------------------------------
# MOJO


@pytest.fixture(scope="module", params=["dct", "vector"])
def mojo_pair(request):
    from benchmarks.torch_ref import mojo as tmojo
    from jaxmotion.models import mojo

    latent = request.param
    nzm, n_low = 4, 2
    jm = mojo.MojoCVAE(dim=D, horizon=T_PRED, nz=nzm, nh_rnn=16, nh_mlp=(20, 12), latent=latent)
    x, y = data(10, B, T_HIS, D), data(11, B, T_PRED, D)
    p = jax.jit(jm.init)(jax.random.key(0), x, y, jax.random.key(1))
    jq = mojo.MojoQ(nz=nzm, nk=K, n_low=n_low, nh_rnn=16, nh_mlp=(32, 24))
    qp = jax.jit(jq.init)(jax.random.key(2), x, jnp.zeros((B, n_low, nzm)))
    tm = convert.mojo_cvae(tmojo.MojoCVAE(D, T_PRED, nz=nzm, nh_rnn=16, nh_mlp=(20, 12), latent=latent), p)
    tq = convert.mojo_q(tmojo.MojoQ(D, nz=nzm, nk=K, n_low=n_low, nh_rnn=16, nh_mlp=(32, 24)), qp)
    return mojo, tmojo, jm, p, jq, qp, tm, tq, x, y


def test_mojo_parameter_counts_match(mojo_pair):
    mojo, tmojo, jm, p, jq, qp, tm, tq, *_ = mojo_pair
    assert n_params(p) == n_torch(tm)
    assert n_params(qp) == n_torch(tq)
    cfg = mojo.MojoConfig()
    big = mojo.cvae_model(cfg, 60, 60)
    shapes = jax.eval_shape(lambda: big.init(jax.random.key(0), jnp.zeros((1, 15, 60)), jnp.zeros((1, 60, 60))))
    assert n_params(shapes) == n_torch(tmojo.MojoCVAE(60, 60))
    q = mojo.q_model(cfg, 60, 50)
    qshapes = jax.eval_shape(lambda: q.init(jax.random.key(0), jnp.zeros((1, 15, 60)), jnp.zeros((1, q.n_low, 16))))
    assert n_params(qshapes) == n_torch(tmojo.MojoQ(60, 16, 50, q.n_low))


def test_mojo_cvae_reconstruction_decoding_and_loss_match(mojo_pair):
    mojo, tmojo, jm, p, _, _, tm, _, x, y = mojo_pair
    key = jax.random.key(7)
    jy, jmu, jlv = jm.apply(p, x, y, key)
    # The twin keeps a band axis for the vector latent too: (b, 1, nz) where jaxmotion has (b, nz).
    banded = lambda a: np.asarray(a).reshape(B, jm.n_bands, jm.nz)  # noqa: E731
    eps = banded(jax.random.normal(key, jmu.shape))
    with torch.no_grad():
        ty, tmu, tlv = tm(tt(x), tt(y), tt(eps))
    rel_close(banded(jmu), tmu)
    rel_close(banded(jlv), tlv)
    rel_close(jy, ty)
    z = data(12, B, K, jm.n_bands, jm.nz)
    with torch.no_grad():
        rel_close(mojo.decode_k(jm, p, x, z.reshape((B, K) + jm.latent_shape)), tmojo.decode_k(tm, tt(x), tt(z)))
    batch = np.concatenate([x, y], axis=1)
    weights = mojo.cvae_loss_weights(mojo.MojoConfig(nz=jm.nz, latent=jm.latent))
    jl, jmet = mojo.cvae_loss(jm, p, batch, key, t_his=T_HIS, **weights)
    with torch.no_grad():
        tl, tmet = tmojo.cvae_loss(tm, tt(batch), tt(eps), t_his=T_HIS)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])


def test_mojo_q_sampling_and_loss_match(mojo_pair):
    mojo, tmojo, jm, p, jq, qp, tm, tq, x, y = mojo_pair
    if jm.n_bands < jq.n_low:
        pytest.skip("the vector latent has one band")
    key = jax.random.key(5)
    # The draws q_latents makes from `key`: eps for the L low bands, N(0, I) for the others.
    k_eps, k_high = jax.random.split(key)
    eps = np.asarray(jax.random.normal(k_eps, (B, jq.n_low, jm.nz)))
    z_high = np.asarray(jax.random.normal(k_high, (B, K, jm.n_bands - jq.n_low, jm.nz)))
    with torch.no_grad():
        ty = tmojo.sample_mojo(tm, tq, tt(x), tt(eps), tt(z_high))
    rel_close(mojo.sample_mojo(jm, p, jq, qp, x, key), ty)
    batch = np.concatenate([x, y], axis=1)
    cfg = mojo.MojoConfig(nz=jm.nz)
    jl, jmet = mojo.q_loss(jq, qp, jm, p, batch, key, t_his=T_HIS, **mojo.q_loss_weights(cfg))
    with torch.no_grad():
        tl, tmet = tmojo.q_loss(tq, tm, tt(batch), tt(eps), tt(z_high), t_his=T_HIS)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])


# ---------------------------------------------------------------------------------------------
# DivSamp (BatchNorm in evaluation mode for decoding and sampling, as at test time)

N_DCT, M = 3, 6


@pytest.fixture(scope="module")
def divsamp_pair():
    from benchmarks.torch_ref import divsamp as tdiv
    from jaxmotion.models import divsamp

    j = D // 3
    jc = divsamp.DivSampCVAE(n_dct=N_DCT, hidden=16, nz=NZ, num_residual=1)
    cx = np.zeros((2, j, 3 * N_DCT), np.float32)
    v = jax.jit(functools.partial(jc.init, train=False))(jax.random.key(0), cx, cx, jax.random.key(1))
    js = divsamp.DivSampSampler(nz=NZ, hidden=16, num_residual=1, num_bases=M, base_dim=10, nh=12)
    sv = jax.jit(functools.partial(js.init, k=K, train=False))(jax.random.key(2), cx, jax.random.key(3))
    # Non-trivial running statistics, so evaluation-mode BatchNorm is really tested.
    rng = np.random.default_rng(20)
    randomise = lambda t: {
        "params": t["params"],
        "batch_stats": jax.tree_util.tree_map_with_path(
            lambda path, a: rng.uniform(0.5, 2.0, a.shape).astype(np.float32) if path[-1].key == "var"
            else rng.normal(0, 0.3, a.shape).astype(np.float32), t["batch_stats"]),
    }
    v, sv = randomise(v), randomise(sv)
    tc = convert.divsamp_cvae(tdiv.DivSampCVAE(j, n_dct=N_DCT, hidden=16, nz=NZ, num_residual=1), v)
    ts = convert.divsamp_sampler(tdiv.DivSampSampler(j, n_dct=N_DCT, nz=NZ, hidden=16, num_residual=1, num_bases=M,
                                                     base_dim=10, nh=12), sv)
    x, y = data(30, B, T_HIS, D), data(31, B, T_PRED, D)
    return divsamp, tdiv, jc, v, js, sv, tc, ts, x, y


def test_divsamp_parameter_counts_match(divsamp_pair):
    divsamp, tdiv, jc, v, js, sv, tc, ts, *_ = divsamp_pair
    count = lambda m: n_torch(m) + sum(b.numel() for n, b in m.named_buffers() if "running" in n)
    assert n_params(v) == count(tc)
    assert n_params(sv) == count(ts)
    c = divsamp.DivSampConfig()
    cx = jnp.zeros((2, 20, 3 * c.n_dct))
    big = jax.eval_shape(lambda: divsamp.cvae_from_config(c).init(jax.random.key(0), cx, cx, jax.random.key(0), train=False))
    assert n_params(big["params"]) == n_torch(tdiv.DivSampCVAE(20))
    sbig = jax.eval_shape(lambda: divsamp.sampler_from_config(c).init(jax.random.key(0), cx, jax.random.key(0), 2, train=False))
    assert n_params(sbig["params"]) == n_torch(tdiv.DivSampSampler(20))


def test_divsamp_cvae_match_in_train_and_eval_mode(divsamp_pair):
    divsamp, tdiv, jc, v, js, sv, tc, ts, x, y = divsamp_pair
    batch = np.concatenate([x, y], axis=1)
    cx = divsamp.condition_nodes(x, T_PRED, N_DCT)
    cw = divsamp.to_nodes(batch, N_DCT)
    rel_close(cx, tdiv.condition_nodes(tt(x), T_PRED, N_DCT))
    rel_close(cw, tdiv.to_nodes(tt(batch), N_DCT))
    key = jax.random.key(8)
    eps = np.asarray(jax.random.normal(key, (B, NZ)))
    # Training-mode BatchNorm updates the running statistics in place: run it on a copy.
    tc_train = copy.deepcopy(tc).train()
    (jn, jmu, jlv), _ = jc.apply(v, cx, cw, key, train=True, mutable=["batch_stats"])
    with torch.no_grad():
        tn, tmu, tlv = tc_train(tt(cx), tt(cw), tt(eps))
    rel_close(jn, tn)
    rel_close(jmu, tmu)
    parents = (-1, 0, 0)  # D = 6: two joints below the root, both children of it
    kw = dict(t_his=T_HIS, parents=parents, beta=0.5, lambda_v=1000.0, lambda_his=1.0, lambda_limb=1000.0)
    jl, (jmet, _) = divsamp.cvae_loss(jc, v, batch, key, **kw)
    with torch.no_grad():
        tl, tmet = tdiv.cvae_loss(tc_train, tt(batch), tt(eps), **kw)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])
    tc.eval()
    jn, _, _ = jc.apply(v, cx, cw, key, train=False)
    with torch.no_grad():
        tn, _, _ = tc(tt(cx), tt(cw), tt(eps))
    rel_close(jn, tn)


def test_divsamp_decoding_and_sampling_match_in_eval_mode(divsamp_pair):
    from jaxmotion import gumbel

    divsamp, tdiv, jc, v, js, sv, tc, ts, x, y = divsamp_pair
    tc.eval()
    ts.eval()
    z = data(32, B, K, NZ)
    cx = divsamp.condition_nodes(x, T_PRED, N_DCT)
    with torch.no_grad():
        rel_close(divsamp.decode_k(jc, v, cx, z, t_his=T_HIS, t_pred=T_PRED),
                  tdiv.decode_k(tc, tt(cx), tt(z), t_his=T_HIS, t_pred=T_PRED))
    key = jax.random.key(9)
    # The draws DivSampSampler makes from `key`: one Gumbel-Softmax W per window, one eps per window.
    k_w, k_eps = jax.random.split(key)
    w = jax.vmap(lambda kk: gumbel.sample_coefficients(kk, K, M, kind="gumbel", tau=1.0))(jax.random.split(k_w, B))
    eps = jax.random.normal(k_eps, (B, 1, NZ))
    with torch.no_grad():
        tz, tmean, tlv = ts(tt(cx), tt(w), tt(eps))
        ty = tdiv.sample_divsamp(tc, ts, tt(x), tt(w), tt(eps), t_pred=T_PRED)
    jz, jmean, jlv = js.apply(sv, cx, key, K, train=False)
    rel_close(jz, tz)
    rel_close(jlv, tlv)
    rel_close(divsamp.decode_k(jc, v, cx, jz, t_his=T_HIS, t_pred=T_PRED), ty)  # one eps per window, as in training
    # The release's evaluation (the default): K independent eps per window.
    with torch.no_grad():
        ty = tdiv.sample_divsamp(tc, ts, tt(x), tt(w), tt(jax.random.normal(k_eps, (B, K, NZ))), t_pred=T_PRED)
    rel_close(divsamp.sample_divsamp(jc, v, js, sv, x, key, K, t_pred=T_PRED), ty)
    # The sampler's loss, sampler BatchNorm in training mode, decoder in evaluation mode.
    batch = np.concatenate([x, y], axis=1)
    kw = dict(lambda_kl=0.5, lambda_acc=40.0, lambda_div=20.0, eta=25.0)
    jl, (jmet, _) = divsamp.sampler_loss(js, sv, jc, v, batch, key, t_his=T_HIS, k=K, **kw)
    with torch.no_grad():
        tl, tmet = tdiv.sampler_loss(copy.deepcopy(ts).train(), tc, tt(batch), tt(w), tt(eps), t_his=T_HIS, **kw)
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])
