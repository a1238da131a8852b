"""DivSamp: DCT node features, CVAE, sampler, losses, BatchNorm handling, training through the CLI."""

import json

import optax

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion import dct, losses
from jaxmotion.cli import main
from jaxmotion.models import divsamp
from jaxmotion.models.divsamp import DivSampConfig
from jaxmotion.train.loop import bn_optimizer, create_state, make_bn_train_step

J, T_HIS, T_PRED, B, NDCT, NZ = 4, 5, 7, 3, 4, 6
D = 3 * J


def _x(b=B, t=T_HIS, seed=0):
    return jnp.asarray(np.random.default_rng(seed).normal(size=(b, t, D)), jnp.float32)


@pytest.fixture(scope="module")
def models():
    cvae = divsamp.DivSampCVAE(n_dct=NDCT, hidden=16, nz=NZ, num_residual=1)
    sampler = divsamp.DivSampSampler(nz=NZ, hidden=16, num_residual=1, num_bases=5, base_dim=8, nh=8)
    cx = divsamp.condition_nodes(_x(), T_PRED, NDCT)
    cv = cvae.init(jax.random.key(0), cx, cx, jax.random.key(1), train=False)
    sv = sampler.init(jax.random.key(2), cx, jax.random.key(3), 4, train=False)
    # Non-trivial running averages, as after training.
    _, upd = cvae.apply(cv, cx, cx, jax.random.key(4), train=True, mutable=["batch_stats"])
    cv = {"params": cv["params"], **upd}
    return cvae, cv, sampler, sv


def test_dct_nodes_round_trip_and_padding():
    seq = _x(t=T_HIS + T_PRED)
    nodes = dct.to_nodes(seq, T_HIS + T_PRED)  # every coefficient kept: exact inverse
    assert nodes.shape == (B, J, 3 * (T_HIS + T_PRED))
    np.testing.assert_allclose(np.asarray(dct.from_nodes(nodes, T_HIS + T_PRED)), np.asarray(seq), atol=1e-5)
    pad = dct.pad_history(_x(), T_PRED)
    np.testing.assert_array_equal(np.asarray(pad[:, T_HIS:]), np.broadcast_to(np.asarray(_x()[:, -1:]), (B, T_PRED, D)))
    # Joint j's features are the coefficients of its own 3 coordinates.
    c = dct.to_nodes(seq, NDCT)
    ref = np.asarray(dct.dct(seq[..., 3:6], NDCT)).transpose(0, 2, 1).reshape(B, -1)
    np.testing.assert_allclose(np.asarray(c[:, 1]), ref, atol=1e-5)


def test_decoder_adds_the_padded_history(models):
    cvae, cv, _, _ = models
    x = _x()
    cx = divsamp.condition_nodes(x, T_PRED, NDCT)
    # With the last graph convolution zeroed, the output is the padded history's own DCT: a constant
    # history then continues as exactly the last pose (the decoder predicts a residual on it).
    zero = jax.tree.map(jnp.zeros_like, cv["params"]["d_out"])
    v = {"params": {**cv["params"], "d_out": zero}, "batch_stats": cv["batch_stats"]}
    still = jnp.broadcast_to(x[:, -1:], x.shape)
    y = divsamp.decode_k(cvae, v, divsamp.condition_nodes(still, T_PRED, NDCT), jnp.ones((B, 2, NZ)), t_his=T_HIS, t_pred=T_PRED)
    np.testing.assert_allclose(np.asarray(y), np.broadcast_to(np.asarray(x[:, None, -1:]), (B, 2, T_PRED, D)), atol=1e-5)
    assert np.asarray(cvae.apply(cv, cx, jnp.ones((B, NZ)), train=False, method=divsamp.DivSampCVAE.decode)).shape == (B, J, 3 * NDCT)


@pytest.mark.slow
def test_any_k_gives_k_futures(models):
    cvae, cv, sampler, sv = models
    for k in (1, 2, 33):
        y = jax.jit(lambda x, key: divsamp.sample_divsamp(cvae, cv, sampler, sv, x, key, k, t_pred=T_PRED))(_x(), jax.random.key(5))
        assert y.shape == (B, k, T_PRED, D) and np.all(np.isfinite(np.asarray(y)))
    assert divsamp.sample_prior(cvae, cv, _x(), jax.random.key(5), 3, t_pred=T_PRED).shape == (B, 3, T_PRED, D)


@pytest.mark.slow
def test_sampling_under_jit_equals_sampling_without(models):
    cvae, cv, sampler, sv = models
    f = lambda x, key: divsamp.sample_divsamp(cvae, cv, sampler, sv, x, key, 6, t_pred=T_PRED)
    eager = f(_x(), jax.random.key(6))
    jitted = jax.jit(f)(_x(), jax.random.key(6))
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), atol=1e-5)
    # Different keys give different futures; within a set the K futures differ.
    other = f(_x(), jax.random.key(7))
    assert float(jnp.abs(other - eager).max()) > 1e-4
    assert float(jnp.abs(eager[:, 0] - eager[:, 1]).max()) > 1e-6


@pytest.mark.slow
def test_eval_mode_futures_do_not_depend_on_the_other_windows(models):
    cvae, cv, sampler, sv = models
    x = _x(b=4, seed=1)
    key = jax.random.key(8)
    cx = divsamp.condition_nodes(x, T_PRED, NDCT)
    z, mean, logvar = sampler.apply(sv, cx, key, 5, train=False)
    assert z.shape == mean.shape == logvar.shape == (4, 5, NZ)
    y_all = divsamp.decode_k(cvae, cv, cx, z, t_his=T_HIS, t_pred=T_PRED)
    y_one = divsamp.decode_k(cvae, cv, cx[2:3], z[2:3], t_his=T_HIS, t_pred=T_PRED)
    np.testing.assert_allclose(np.asarray(y_all[2:3]), np.asarray(y_one), atol=1e-5)


def test_decode_k_equals_decoding_each_latent_alone(models):
    # decode_k folds K into the batch; each future must be what the decoder gives for its latent alone.
    cvae, cv, sampler, sv = models
    x = _x(b=3, seed=2)
    cx = divsamp.condition_nodes(x, T_PRED, NDCT)
    z = jax.random.normal(jax.random.key(4), (3, 4, NZ))
    y = divsamp.decode_k(cvae, cv, cx, z, t_his=T_HIS, t_pred=T_PRED)
    assert y.shape == (3, 4, T_PRED, x.shape[-1])
    for k in range(4):
        nodes = cvae.apply(cv, cx, z[:, k], train=False, method=divsamp.DivSampCVAE.decode)
        alone = divsamp.from_nodes(nodes, T_HIS + T_PRED)[:, T_HIS:]
        np.testing.assert_allclose(np.asarray(y[:, k]), np.asarray(alone), atol=1e-5)


@pytest.mark.slow
def test_one_basis_vector_gives_one_gaussian():
    # M = 1: every row of W is [1], all K points coincide, so all K Gaussians are the same.
    s = divsamp.DivSampSampler(nz=NZ, hidden=8, num_residual=0, num_bases=1, base_dim=4, nh=8)
    cx = divsamp.condition_nodes(_x(), T_PRED, NDCT)
    v = s.init(jax.random.key(0), cx, jax.random.key(1), 3, train=False)
    _, mean, logvar = s.apply(v, cx, jax.random.key(2), 7, train=False)
    np.testing.assert_allclose(np.asarray(mean), np.broadcast_to(np.asarray(mean[:, :1]), mean.shape), atol=1e-6)
    np.testing.assert_allclose(np.asarray(logvar), np.broadcast_to(np.asarray(logvar[:, :1]), logvar.shape), atol=1e-6)


@pytest.mark.parametrize("pi,coef", [("learned_shared", "gumbel"), ("learned_per_sample", "gumbel"), ("uniform", "gaussian")])
@pytest.mark.slow
def test_sampler_options(pi, coef):
    s = divsamp.DivSampSampler(nz=NZ, hidden=8, num_residual=0, num_bases=4, base_dim=4, nh=8, pi=pi, coefficients=coef)
    cx = divsamp.condition_nodes(_x(), T_PRED, NDCT)
    v = s.init(jax.random.key(0), cx, jax.random.key(1), 3, train=False)
    assert ("pi_logits" in v["params"]) == (pi == "learned_shared")
    assert ("pi_head" in v["params"]) == (pi == "learned_per_sample")
    z, _, _ = s.apply(v, cx, jax.random.key(2), 5, train=False)
    assert z.shape == (B, 5, NZ)


@pytest.mark.slow
def test_hinge_diversity():
    y = jnp.asarray(np.random.default_rng(0).normal(size=(6, 4, 3)), jnp.float32)
    d = np.linalg.norm(np.asarray(y).reshape(6, 1, -1) - np.asarray(y).reshape(1, 6, -1), axis=-1)
    far = float(d[np.triu_indices(6, 1)].min())
    # Zero when every pair is farther apart than eta; no gradient either.
    assert float(losses.hinge_diversity(y, far - 1e-3)) == 0.0
    assert float(jnp.abs(jax.grad(losses.hinge_diversity)(y, far - 1e-3)).max()) == 0.0
    # Otherwise the mean over pairs i != j of max(0, eta - d_ij).
    eta = float(np.median(d[np.triu_indices(6, 1)]))
    ref = np.mean([max(0.0, eta - d[i, j]) for i in range(6) for j in range(6) if i != j])
    np.testing.assert_allclose(float(losses.hinge_diversity(y, eta)), ref, rtol=1e-5)
    # Identical samples: finite gradient.
    same = jnp.zeros((3, 4))
    assert float(losses.hinge_diversity(same, 1.0)) == pytest.approx(1.0, abs=1e-5)
    assert np.all(np.isfinite(np.asarray(jax.grad(losses.hinge_diversity)(same, 1.0))))


def test_bone_lengths():
    # Root at the origin, joint 1 at (0, 0, 2) child of the root, joint 2 at (3, 0, 2) child of joint 1.
    frames = jnp.array([[0.0, 0, 2, 3, 0, 2]])
    np.testing.assert_allclose(np.asarray(divsamp.bone_lengths(frames, (-1, 0, 1))), [[2.0, 3.0]], atol=1e-6)


def test_bone_vectors_by_product_equal_the_gathered_differences():
    """`frames @ bone_matrix` is exactly `p_i - p_parent(i)` (a branching tree), and so are its gradients."""
    parents = (-1, 0, 1, 2, 0, 4, 1, 6, 7, 1, 9, 2)  # spine, a leg, two arms from joint 1, a head
    parents = parents[:5] + (6,) + parents[6:]  # joint 5's parent listed after it: order does not matter
    frames = jnp.asarray(np.random.default_rng(0).normal(size=(4, 7, 3 * (len(parents) - 1))), jnp.float32)

    def gathered(f):
        pos = jnp.concatenate([jnp.zeros(f.shape[:-1] + (1, 3)), f.reshape(f.shape[:-1] + (-1, 3))], axis=-2)
        child = np.arange(1, len(parents))
        return pos[..., child, :] - pos[..., np.asarray(parents)[child], :]

    np.testing.assert_array_equal(np.asarray(divsamp.bone_vectors(frames, parents)), np.asarray(gathered(frames)))
    w = jnp.asarray(np.random.default_rng(1).normal(size=(len(parents) - 1, 3)), jnp.float32)
    g_new = jax.grad(lambda f: jnp.sum(divsamp.bone_vectors(f, parents) * w))(frames)
    g_old = jax.grad(lambda f: jnp.sum(gathered(f) * w))(frames)
    np.testing.assert_allclose(np.asarray(g_new), np.asarray(g_old), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("parents", [(-1, 0, -1), (-1, 1, 0), (-1, 0, 3)])
def test_bone_matrix_refuses_a_joint_without_a_parent(parents):
    with pytest.raises(ValueError, match="parent"):
        divsamp.bone_matrix(parents)


def test_bone_vectors_refuse_frames_of_another_skeleton():
    with pytest.raises(ValueError, match="do not fit a skeleton of 2 joints"):
        divsamp.bone_lengths(jnp.zeros((1, 6)), (-1, 0))


@pytest.mark.slow
def test_sampler_step_trains_the_sampler_only_and_updates_its_statistics(models):
    cvae, cv, sampler, sv = models
    tx = bn_optimizer(optax.adam(1e-2))
    loss = lambda v, frozen, b, k: divsamp.sampler_loss(
        sampler, v, cvae, frozen, b, k, t_his=T_HIS, k=5, lambda_kl=0.1, lambda_acc=1.0, lambda_div=1.0, eta=5.0
    )
    step = jax.jit(make_bn_train_step(loss, tx))
    state = create_state(dict(sv), tx, frozen=cv)
    batch = _x(b=8, t=T_HIS + T_PRED, seed=3)
    new, metrics = step(state, batch, jax.random.key(0))
    assert set(metrics) >= {"loss", "div", "recon", "kld", "grad_norm"}
    # The frozen decoder and its running averages are untouched; the sampler's weights and statistics move.
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(np.asarray(a), np.asarray(b)), new.frozen, cv)
    moved = lambda a, b: float(jnp.abs(a - b).max()) > 0
    assert moved(new.params["params"]["bases"]["kernel"], sv["params"]["bases"]["kernel"])
    assert moved(new.params["batch_stats"]["bases_bn"]["mean"], sv["batch_stats"]["bases_bn"]["mean"])
    # Batch statistics are not optimiser parameters: no Adam moments are kept for them.
    n_opt = sum(x.size for x in jax.tree.leaves(new.opt_state))
    n_par = sum(x.size for x in jax.tree.leaves(sv["params"]))
    assert n_opt == 2 * n_par + 1


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match="coefficients"):
        divsamp.check_config(DivSampConfig(coefficients="dirichlet"))
    with pytest.raises(ValueError, match="pi"):
        divsamp.check_config(DivSampConfig(pi="learned_shared", coefficients="uniform"))
    with pytest.raises(ValueError, match="diversity"):
        divsamp.check_config(DivSampConfig(diversity="l2"))
    with pytest.raises(ValueError, match="nk"):
        divsamp.check_config(DivSampConfig(nk=1))


TINY = """
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig
def get_config():
    return Config(name="tiny_divsamp", action_metrics=False, method="divsamp", eval_k=(4,), ckpt_every=2, log_every=2, max_test_windows=12,
                  eval_batch=12, method_config=DivSampConfig(hidden=16, nz=8, cvae_residual=1, sampler_residual=0, num_bases=4,
                  base_dim=8, nh=8, cvae_num_steps=4, cvae_batch_size=8, num_steps=NSTEPS, batch_size=4, nk=4,
                  lr_fix_fraction=1.0))
"""


@pytest.mark.slow
def test_cli_trains_both_stages_resumes_exactly_and_evaluates(tmp_path):
    cfg_half, cfg_full = tmp_path / "half.py", tmp_path / "full.py"
    cfg_half.write_text(TINY.replace("NSTEPS", "2"))
    cfg_full.write_text(TINY.replace("NSTEPS", "4"))
    # Interrupted after 2 sampler steps, then resumed to 4, vs 4 in one go: the same variables,
    # BatchNorm statistics included (a constant lr, so the two configs' schedules agree).
    assert main(["train", "--config", str(cfg_half), "--workdir", str(tmp_path / "a")]) == 0
    assert main(["train", "--config", str(cfg_full), "--workdir", str(tmp_path / "a"), "--resume"]) == 0
    assert main(["train", "--config", str(cfg_full), "--workdir", str(tmp_path / "b")]) == 0
    assert main(["eval", "--config", str(cfg_full), "--workdir", str(tmp_path / "a")]) == 0
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = load_config(cfg_full)
    prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
    pa, pb = experiment.restore(cfg, prep, tmp_path / "a"), experiment.restore(cfg, prep, tmp_path / "b")
    assert sorted(pa) == sorted(pb) == ["cvae", "sampler"]
    jax.tree.map(lambda a, b: np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-6), pa, pb)
    records = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert {r["method"] for r in records} == {"zero_velocity", "divsamp_cvae", "divsamp"}
    m = {r["method"]: r["metrics"] for r in records}
    assert m["zero_velocity"]["APD"] == 0.0 and m["divsamp"]["APD"] > 0.0 and m["divsamp_cvae"]["APD"] > 0.0


@pytest.mark.slow
def test_test_time_noise_is_independent_per_sample(models):
    cvae, cv, sampler, sv = models
    x = _x(b=2, t=T_HIS, seed=9)
    key = jax.random.key(4)
    cx = divsamp.condition_nodes(x, T_PRED, NDCT)
    y = divsamp.sample_divsamp(cvae, cv, sampler, sv, x, key, 6, t_pred=T_PRED)  # the release's evaluation
    assert y.shape == (2, 6, T_PRED, x.shape[-1])
    # The same points and Gaussians as training's shared draw, different noise: z_k - mean_k is one vector
    # scaled per k when shared (training), K independent draws at test time.
    z_s, mean, logvar = sampler.apply(sv, cx, key, 6, train=False)
    z_i, mean_i, _ = sampler.apply(sv, cx, key, 6, train=False, shared_eps=False)
    np.testing.assert_array_equal(np.asarray(y), np.asarray(divsamp.decode_k(cvae, cv, cx, z_i, t_his=T_HIS, t_pred=T_PRED)))
    np.testing.assert_array_equal(np.asarray(mean), np.asarray(mean_i))
    eps_s = (z_s - mean) / jnp.exp(0.5 * logvar)
    eps_i = (z_i - mean) / jnp.exp(0.5 * logvar)
    np.testing.assert_allclose(np.asarray(eps_s), np.asarray(jnp.broadcast_to(eps_s[:, :1], eps_s.shape)), atol=1e-4)
    assert float(jnp.abs(eps_i[:, 0] - eps_i[:, 1]).max()) > 0.1


def test_the_release_angle_term_adds_lambda_times_gsps_angle_loss():
    from jaxmotion.data.datasets import HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS
    from jaxmotion.models import gsps

    cvae = divsamp.DivSampCVAE(n_dct=NDCT, hidden=16, nz=NZ, num_residual=1)
    batch = jnp.asarray(np.random.default_rng(3).normal(size=(4, T_HIS + T_PRED, 42)), jnp.float32)
    cx = divsamp.condition_nodes(batch[:, :T_HIS], T_PRED, NDCT)
    v = cvae.init(jax.random.key(0), cx, cx, jax.random.key(1), train=False)
    roles = gsps.angle_roles(HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS)
    bounds = jnp.tile(jnp.array([[-0.2, 0.2]], jnp.float32), (len(gsps.ANGLE_NAMES), 1))  # tight: violated
    kw = dict(t_his=T_HIS, parents=HUMANEVA_PARENTS, beta=0.1, lambda_v=1.0, lambda_his=1.0, lambda_limb=1.0)
    base, (m0, _) = divsamp.cvae_loss(cvae, v, batch, jax.random.key(2), **kw)
    with_angle, (m1, _) = divsamp.cvae_loss(cvae, v, batch, jax.random.key(2), lambda_angle=100.0, angle_bounds=bounds,
                                            roles=roles, **kw)
    assert "angle" not in m0 and float(m1["angle"]) > 0
    np.testing.assert_allclose(float(with_angle - base), 100.0 * float(m1["angle"]), rtol=1e-4)


def test_the_expanded_cvae_set_swaps_futures_for_pseudo_ones():
    from types import SimpleNamespace

    from jaxmotion.data.windows import TrainSampler
    from jaxmotion.methods.divsamp import cvae_batches

    rng = np.random.default_rng(0)
    frames = [np.cumsum(rng.normal(size=(60, D)), axis=0).astype(np.float32) * 0.1 for _ in range(3)]
    prep = SimpleNamespace(dataset=SimpleNamespace(t_his=T_HIS, t_pred=T_PRED), sampler=TrainSampler(frames, T_HIS + T_PRED))
    cfg = lambda p: DivSampConfig(cvae_batch_size=16, cvae_pseudo_prob=p, mm_candidate_stride=3,  # noqa: E731
                                  mm_his_threshold=1e9, mm_pred_threshold=0.0)
    plain = cvae_batches(prep, cfg(0.0))(np.random.default_rng(1))
    np.testing.assert_array_equal(plain, prep.sampler.sample(np.random.default_rng(1), 16))
    swapped = cvae_batches(prep, cfg(1.0))(np.random.default_rng(1))
    np.testing.assert_array_equal(swapped[:, :T_HIS], plain[:, :T_HIS])  # the history is kept
    pool = np.concatenate([np.stack([f[s:s + T_HIS + T_PRED] for s in range(0, 60 - T_HIS - T_PRED + 1, 3)]) for f in frames])
    for y in swapped[:, T_HIS:]:  # every future is a candidate's
        assert np.min(np.abs(pool[:, T_HIS:] - y).max(axis=(1, 2))) == 0.0
    assert np.mean(np.any(swapped != plain, axis=(1, 2))) > 0.5
    with pytest.raises(ValueError, match="cvae_pseudo_prob"):
        DivSampConfig(cvae_pseudo_prob=1.5)
