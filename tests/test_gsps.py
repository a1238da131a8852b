"""GSPS: the pose prior (exact inverse, log-det, density of valid poses), angle limits, the generator and its objective."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion.data.synthetic import SKELETON, make_synthetic
from jaxmotion.data.windows import sequence_frames
from jaxmotion.models import gsps

PARENTS = SKELETON.parents
ROLES = gsps.angle_roles(SKELETON.names, SKELETON.parents)


@functools.lru_cache(maxsize=1)
def _data():
    ds = make_synthetic(0)
    return np.concatenate(sequence_frames(ds.train)), np.concatenate(sequence_frames(ds.test))


def _prior(dim=48, seed=0):
    prior = gsps.PosePrior(dim=dim, n_layers=3)
    return prior, prior.init(jax.random.key(seed), jnp.zeros((1, dim)))


@pytest.mark.slow
def test_prior_inverse_inverts():
    prior, params = _prior()
    d = jax.random.normal(jax.random.key(1), (64, 48))
    z, _ = prior.apply(params, d)
    back = prior.apply(params, z, method=gsps.PosePrior.inverse)
    np.testing.assert_allclose(back, d, atol=2e-4)
    assert float(jnp.mean(z < 0)) > 0.2  # the PReLU's negative branch was exercised


@pytest.mark.slow
def test_prior_logdet_equals_slogdet_of_jacobian():
    prior, params = _prior(dim=12)
    for i in range(4):
        d = jax.random.normal(jax.random.key(10 + i), (12,))
        _, logdet = prior.apply(params, d)
        jac = jax.jacfwd(lambda v: prior.apply(params, v)[0])(d)
        sign, ref = jnp.linalg.slogdet(jac)
        assert sign != 0
        np.testing.assert_allclose(logdet, ref, rtol=1e-4, atol=1e-4)


def test_householder_product_is_orthogonal():
    q = gsps.householder_product(jax.random.normal(jax.random.key(0), (7, 7)))
    np.testing.assert_allclose(q @ q.T, np.eye(7), atol=1e-5)


def _householder_one_by_one(u):
    q = jnp.eye(u.shape[-1])
    for v in u:
        v = v / jnp.linalg.norm(v)
        q = q - 2.0 * (q @ v)[:, None] * v[None, :]  # q H_i
    return q


def test_householder_product_equals_the_reflections_applied_one_by_one():
    u = jax.random.normal(jax.random.key(0), (42, 42))
    np.testing.assert_allclose(gsps.householder_product(u), _householder_one_by_one(u), atol=1e-6)


def _prior_loss_reference(params, frames):
    # The prior's loss written out plainly: limb directions divided by their norms, each reflection normalised
    # in turn, f Q R as two products.
    v = gsps.bone_vectors(frames, PARENTS)
    d = (v / jnp.maximum(jnp.linalg.norm(v, axis=-1, keepdims=True), 1e-8)).reshape(frames.shape)
    logdet = 0.0
    for i in range(3):
        lin = params["params"][f"linqr_{i}"]
        r = jnp.triu(lin["r"], 1) + jnp.diag(jnp.exp(jnp.diag(lin["r"])))
        d = d @ _householder_one_by_one(lin["householder"]) @ r + lin["bias"]
        logdet = logdet + jnp.sum(jnp.diag(lin["r"]))
        if i < 2:
            a = params["params"][f"prelu_{i}"]["log_slope"]
            logdet = logdet + a * jnp.sum(d < 0, axis=-1)
            d = jnp.where(d < 0, jnp.exp(a) * d, d)
    return -jnp.mean(gsps.std_normal_log_prob(d) + logdet)


@pytest.mark.slow
def test_prior_trains_to_the_same_parameters_as_the_plain_formulas():
    # 20 Adam steps (lr 1e-2, the release's) of `prior_loss` (directions normalised before the reflections' loop,
    # Q R formed once, limb directions by a reciprocal square root) and of the formulas written out plainly: the same losses and parameters to float32 rounding.
    train, _ = _data()
    prior, p0 = _prior(dim=train.shape[1])
    opt = optax.adam(1e-2)
    rng = np.random.default_rng(0)
    frames = [jnp.asarray(train[rng.integers(0, len(train), 256)]) for _ in range(20)]

    def run(loss_fn):
        step = jax.jit(lambda p, o, f: _adam_step(opt, lambda p: loss_fn(p, f), p, o))
        p, o, losses = p0, opt.init(p0), []
        for f in frames:
            p, o, loss = step(p, o, f)
            losses.append(float(loss))
        return p, losses

    p_fast, l_fast = run(lambda p, f: gsps.prior_loss(prior, p, f, parents=PARENTS)[0])
    p_ref, l_ref = run(_prior_loss_reference)
    np.testing.assert_allclose(l_fast, l_ref, rtol=1e-5, atol=1e-5)
    moved = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(jax.tree.leaves(p_ref), jax.tree.leaves(p0)))
    assert moved > 0.05  # the steps moved the parameters by far more than the tolerance
    for a, b in zip(jax.tree.leaves(p_fast), jax.tree.leaves(p_ref)):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)


def _adam_step(opt, loss_fn, p, o):
    loss, g = jax.value_and_grad(loss_fn)(p)
    upd, o = opt.update(g, o, p)
    return optax.apply_updates(p, upd), o, loss


def test_limb_directions_equal_bone_vectors_over_their_norms_with_the_same_gradients():
    # The squared lengths added from the three coordinates (no size-3 reduction) against the plain formula.
    frames = jnp.asarray(_data()[0][:16])
    plain = lambda f: (lambda v: v / jnp.linalg.norm(v, axis=-1, keepdims=True))(gsps.bone_vectors(f, PARENTS)).reshape(f.shape)  # noqa: E731
    np.testing.assert_allclose(gsps.limb_directions(frames, PARENTS), plain(frames), rtol=1e-6, atol=1e-6)
    weights = jax.random.normal(jax.random.key(0), frames.shape)
    grad = lambda fn: jax.grad(lambda f: jnp.sum(weights * fn(f)))(frames)  # noqa: E731
    np.testing.assert_allclose(grad(lambda f: gsps.limb_directions(f, PARENTS)), grad(plain), rtol=1e-5, atol=1e-5)


def test_limb_directions_are_unit_vectors():
    train, _ = _data()
    d = gsps.limb_directions(jnp.asarray(train[:10]), PARENTS).reshape(10, -1, 3)
    np.testing.assert_allclose(jnp.linalg.norm(d, axis=-1), 1.0, atol=1e-5)


def _bend_knee_backwards(frames: np.ndarray) -> np.ndarray:
    """Rotates each shank 180 degrees about its thigh: the knee bends the other way, bone lengths kept."""
    pos = np.concatenate([np.zeros_like(frames[:, :3]), frames], axis=1).reshape(len(frames), -1, 3).copy()
    for hip, knee, foot in ((ROLES["l_hip"], ROLES["l_knee"], ROLES["l_foot"]), (ROLES["r_hip"], ROLES["r_knee"], ROLES["r_foot"])):
        t = pos[:, knee] - pos[:, hip]
        t /= np.linalg.norm(t, axis=-1, keepdims=True)
        s = pos[:, foot] - pos[:, knee]
        pos[:, foot] = pos[:, knee] + 2 * np.sum(s * t, -1, keepdims=True) * t - s
    return pos[:, 1:].reshape(len(frames), -1)


def _knee_flexion(frames: np.ndarray) -> np.ndarray:
    pos = np.concatenate([np.zeros_like(frames[:, :3]), frames], axis=1).reshape(len(frames), -1, 3)
    t = pos[:, ROLES["l_knee"]] - pos[:, ROLES["l_hip"]]
    s = pos[:, ROLES["l_foot"]] - pos[:, ROLES["l_knee"]]
    return np.arccos(np.clip(np.sum(t * s, -1) / np.linalg.norm(t, axis=-1) / np.linalg.norm(s, axis=-1), -1, 1))


@pytest.mark.slow  # trains the prior for 300 steps (~4 s)
def test_trained_prior_prefers_real_poses_to_knees_bent_backwards():
    train, test = _data()
    prior = gsps.PosePrior(dim=48, n_layers=3)
    params = prior.init(jax.random.key(0), jnp.zeros((1, 48)))
    tx = optax.chain(optax.add_decayed_weights(1e-3), optax.adam(1e-2))
    opt = tx.init(params)

    @jax.jit
    def step(params, opt, frames):
        (loss, _), g = jax.value_and_grad(gsps.prior_loss, argnums=1, has_aux=True)(prior, params, frames, parents=PARENTS)
        up, opt = tx.update(g, opt, params)
        return optax.apply_updates(params, up), opt, loss

    rng = np.random.default_rng(0)
    for _ in range(300):
        params, opt, loss = step(params, opt, jnp.asarray(train[rng.integers(0, len(train), 512)]))
    assert np.isfinite(float(loss))
    bent = test[_knee_flexion(test) > np.deg2rad(20)]
    assert len(bent) > 100
    real = gsps.prior_nll(prior, params, jnp.asarray(bent), PARENTS)
    broken = gsps.prior_nll(prior, params, jnp.asarray(_bend_knee_backwards(bent)), PARENTS)
    # Lower NLL = higher density on held-out subjects' real poses, for nearly every pose.
    assert float(jnp.mean(real < broken)) > 0.95
    assert float(jnp.median(broken - real)) > 10.0


# ----------------------------------------------------------------------------------------------
# Angle limits.


def test_angle_roles_from_names_of_every_skeleton():
    from jaxmotion.data.datasets import HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS

    bandai = ("Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L", "Shoulder_R",
              "UpperArm_R", "LowerArm_R", "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R",
              "LowerLeg_R", "Foot_R", "Toes_R")
    bandai_parents = (-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19)
    r = gsps.angle_roles(bandai, bandai_parents)
    assert (r["l_knee"], r["r_shoulder"], r["thorax"], r["l_wrist"]) == (14, 10, 2, 8)
    r = gsps.angle_roles(HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS)
    assert (r["l_knee"], r["r_foot"], r["thorax"], r["head"]) == (9, 13, 1, 14)
    # The release's HumanEva-I parts (`humaneva.yml`): legs [7..12], then the rest.
    assert gsps.body_parts(HUMANEVA_JOINT_NAMES, HUMANEVA_PARENTS, "lower_upper") == ((7, 8, 9, 10, 11, 12), (0, 1, 2, 3, 4, 5, 6, 13))
    # ... and Human3.6M's (`h36m.yml`), whose 17-joint layout the synthetic skeleton shares.
    assert gsps.body_parts(SKELETON.names, PARENTS, "lower_upper") == (tuple(range(6)), tuple(range(6, 16)))
    with pytest.raises(ValueError, match="no joint for role l_hip"):
        gsps.angle_roles(("Hips", "Head"), (-1, 0))


@pytest.mark.slow
def test_measured_bounds_hold_real_poses_and_reject_backward_knees():
    train, test = _data()
    bounds = gsps.measure_angle_bounds(train[::5], ROLES, 0.1, margin=0.05)
    assert bounds.shape == (len(gsps.ANGLE_NAMES), 2) and np.all(bounds[:, 0] <= bounds[:, 1])
    frac_real = float(gsps.violation_fraction(jnp.asarray(test)[None], ROLES, jnp.asarray(bounds))[0])
    assert frac_real < 0.01
    bent = test[_knee_flexion(test) > np.deg2rad(20)]
    cos = gsps.angle_cosines(jnp.asarray(_bend_knee_backwards(bent)), ROLES)
    viol = gsps.angle_violations(cos, jnp.asarray(bounds))
    knee = gsps.ANGLE_NAMES.index("Leg2HipPlane_l")
    assert float(jnp.mean(viol[:, knee] > 0)) > 0.95
    assert float(gsps.angle_loss(cos, jnp.asarray(bounds))) > 0.0
    assert float(gsps.angle_loss(gsps.angle_cosines(jnp.asarray(bent), ROLES), jnp.asarray(bounds))) < 1e-3


def test_angle_loss_is_mean_squared_violation_per_family_and_ignores_open_bounds():
    a = len(gsps.ANGLE_NAMES)
    bounds = np.tile(np.array([[-0.5, 0.5]], np.float32), (a, 1))
    bounds[1] = [-0.99, 0.99]  # Spine2Hip_r: both bounds open (|bound| > 0.98), never penalised
    cos = np.zeros((3, a), np.float32)
    cos[0, 0], cos[1, 0] = 0.7, -0.9  # Spine2Hip_l leaves [lo, hi] by 0.2 and 0.4
    cos[:, 1] = 1.0
    cos[2, 2] = 0.6  # Leg2HipPlane_l by 0.1
    got = float(gsps.angle_loss(jnp.asarray(cos), jnp.asarray(bounds)))
    np.testing.assert_allclose(got, (0.2**2 + 0.4**2) / 2 + 0.1**2, rtol=1e-5)


# ----------------------------------------------------------------------------------------------
# Generator, objective, pseudo ground truth.

PARTS = gsps.body_parts(SKELETON.names, PARENTS, "lower_upper")


def _gen(parts=PARTS, hidden=16):
    gen = gsps.GSPSGenerator(parts=parts, hidden=hidden, num_stage=1)
    nodes = jnp.zeros((2, 16, 3 * 5))
    v = gen.init(jax.random.key(0), nodes, jnp.zeros((2, len(parts), 8)), train=False)
    return gen, v


@pytest.mark.slow
def test_later_parts_never_change_earlier_parts_so_the_lower_body_can_be_fixed():
    train, _ = _data()
    gen, v = _gen()
    x = jnp.asarray(np.stack([train[0:15], train[300:315]]))
    z = gsps.part_control_noise(jax.random.key(3), 2, 6, 2, 8, fixed=(0,))
    seq, _ = gsps.generate(gen, v, x, z, t_pred=60, n_pre=5, train=False)
    assert seq.shape == (2, 6, 75, 48)
    lower, upper = gsps.part_coords(PARTS)
    spread = lambda c: float(jnp.max(jnp.std(seq[..., c], axis=1)))  # noqa: E731
    assert spread(lower) < 1e-6 < 1e-3 < spread(upper)
    z = gsps.part_control_noise(jax.random.key(3), 2, 6, 2, 8, fixed=(1,))
    seq, _ = gsps.generate(gen, v, x, z, t_pred=60, n_pre=5, train=False)
    assert spread(lower) > 1e-3 and spread(upper) > 1e-3  # the upper body sees the varying lower body


def test_five_part_split_predicts_every_joint_once():
    parts = gsps.body_parts(SKELETON.names, PARENTS, "five")
    assert sorted(j for p in parts for j in p) == list(range(16))
    gen, v = _gen(parts)
    out = gen.apply(v, jnp.ones((2, 16, 15)), jnp.ones((2, 5, 8)), train=False)
    assert out.shape == (2, 16, 15) and bool(jnp.all(jnp.isfinite(out)))


def test_training_noise_grid_shares_first_part_noise_across_nk2():
    z = gsps.training_noise(jax.random.key(0), 2, 2, 3, 4, 8).reshape(2, 3, 4, 2, 8)
    np.testing.assert_array_equal(z[:, :, 0, 0], z[:, :, 3, 0])
    assert float(jnp.min(jnp.abs(z[:, 0, :, 0] - z[:, 1, :, 0]))) > 0
    assert float(jnp.min(jnp.abs(z[:, :, 0, 1] - z[:, :, 1, 1]))) > 0


def test_pseudo_futures_follow_the_release_thresholds():
    train, _ = _data()
    pool = gsps.candidate_pool([train[:3000]], 15, 60, 15)
    w = pool[[10, 50]]
    fut, mask = gsps.pseudo_futures(w, pool, np.random.default_rng(0), t_his=15, his_threshold=0.05, pred_threshold=0.1, num=10)
    assert fut.shape == (2, 10, 60, 48) and mask.any()
    j = 16
    for i in range(2):
        for f in fut[i][mask[i]]:
            cand = [c for c in pool if np.array_equal(c[15:], f)][0]
            assert np.linalg.norm((cand[14] - w[i, 14]).reshape(j, 3), axis=-1).mean() <= 0.05
            assert np.linalg.norm((f - w[i, 15:]).reshape(60, j, 3), axis=-1).mean() >= 0.1
        assert not fut[i][~mask[i]].any()



def test_pseudo_futures_draw_uniformly_from_every_qualified_candidate():
    # A brute-force qualified set on a small synthetic pool: every qualified candidate is drawn
    # when there are no more than `num`, and each is drawn equally often when there are more.
    rng = np.random.default_rng(1)
    t_his, t, j = 3, 8, 2
    pool = rng.normal(0, 0.1, (300, t, j * 3)).astype(np.float32)
    w = pool[:2]
    last = lambda x: x[..., t_his - 1, :].reshape(*x.shape[:-2], j, 3)
    qual = []
    for i in range(2):
        dh = np.linalg.norm(last(pool) - last(w[i]), axis=-1).mean(-1)
        dp = np.linalg.norm((pool[:, t_his:] - w[i, t_his:]).reshape(-1, t - t_his, j, 3), axis=-1).mean((1, 2))
        qual.append(np.flatnonzero((dh <= 0.15) & (dp >= 0.2)))
    assert 20 < len(qual[0]) < 200 and 20 < len(qual[1]) < 200
    fut, mask = gsps.pseudo_futures(w, pool, rng, t_his=t_his, his_threshold=0.15, pred_threshold=0.2, num=300)
    for i in range(2):
        assert mask[i].sum() == len(qual[i])
        np.testing.assert_array_equal(np.sort(fut[i][mask[i]].sum((1, 2))), np.sort(pool[qual[i], t_his:].sum((1, 2))))
    counts = np.zeros(len(pool))
    trials, num = 400, 10
    for _ in range(trials):
        fut, mask = gsps.pseudo_futures(w[:1], pool, rng, t_his=t_his, his_threshold=0.15, pred_threshold=0.2, num=num)
        assert mask.sum() == num
        drawn = [int(np.flatnonzero((pool[:, t_his:] == f).all((1, 2)))[0]) for f in fut[0]]
        assert len(set(drawn)) == num and set(drawn) <= set(qual[0])
        counts[drawn] += 1
    expected = trials * num / len(qual[0])
    chi2 = float(((counts[qual[0]] - expected) ** 2 / expected).sum())
    assert chi2 < len(qual[0]) + 5 * np.sqrt(2 * len(qual[0])), chi2  # mean + 5 sd of chi-square


def test_best_of_errors_gram_matches_the_pairwise_differences():
    # Bandai's scale: futures relative to the hips (~0.5 m), samples ~0.05-0.5 m from the truth, one
    # sample equal to a pseudo future (distance exactly 0 in the pairwise form).
    rng = np.random.default_rng(0)
    b, k, m, t, d = 3, 12, 5, 60, 60
    y = rng.normal(0, 0.5, (b, t, d)).astype(np.float32)
    y_g = (y[:, None] + rng.normal(0, 1, (b, k, 1, 1)) * rng.normal(0, 0.05, (b, k, t, d))).astype(np.float32)
    mm = (y[:, None] + rng.normal(0, 0.1, (b, m, t, d))).astype(np.float32)
    mm[1, 2] = y_g[1, 7]
    w = rng.normal(size=(b, k, m)).astype(np.float32)

    def f(how):
        def scalar(y_g):
            err, err_mm = gsps._best_of_errors(y_g, jnp.asarray(y), jnp.asarray(mm), how)
            return jnp.sum(jnp.min(err, 1)) + jnp.sum(jnp.min(err_mm, 1)) + jnp.sum(w * err_mm), (err, err_mm)
        return jax.jit(jax.value_and_grad(scalar, has_aux=True))(jnp.asarray(y_g))

    (v_p, (e_p, em_p)), g_p = f("pairwise")
    (v_g, (e_g, em_g)), g_g = f("gram")
    np.testing.assert_allclose(e_g, e_p, rtol=1e-6)
    np.testing.assert_allclose(em_g, em_p, rtol=1e-5, atol=2e-4)  # errors ~ 0.5-36, atol: float32 rounding of |a|^2 ~ 900
    assert float(em_g[1, 7, 2]) < 2e-4
    np.testing.assert_allclose(v_g, v_p, rtol=1e-5)
    np.testing.assert_allclose(g_g, g_p, rtol=1e-4, atol=1e-4 * float(jnp.max(jnp.abs(g_p))))
    assert np.array_equal(np.argmin(em_g, 1), np.argmin(em_p, 1))
    with pytest.raises(ValueError, match="best_of"):
        gsps._best_of_errors(jnp.asarray(y_g), jnp.asarray(y), jnp.asarray(mm), "cdist")


@pytest.mark.slow
def test_generator_loss_is_finite_and_differentiable():
    train, _ = _data()
    gen, v = _gen()
    prior, pp = _prior()
    pool = gsps.candidate_pool([train[:3000]], 15, 60, 15)
    w = pool[[3, 40]]
    mm, mask = gsps.pseudo_futures(w, pool, np.random.default_rng(0), t_his=15, his_threshold=0.05, pred_threshold=0.1, num=4)
    bounds = jnp.asarray(gsps.measure_angle_bounds(train[::10], ROLES, 0.1))
    loss_fn = functools.partial(
        gsps.generator_loss, gen, prior=prior, prior_params=pp, t_his=15, parents=PARENTS, parts=PARTS, roles=ROLES,
        angle_bounds=bounds, n_pre=5, nz=8, nk1=3, nk2=2, lambda_his=100.0, lambda_limb=500.0, lambda_div_first=8.0,
        lambda_div_rest=25.0, alpha=100.0, beta=300.0, lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01,
        prior_stride=3, lambda_angle=100.0,
    )
    batch = {"window": jnp.asarray(w), "mm": jnp.asarray(mm), "mm_mask": jnp.asarray(mask, jnp.float32)}
    grad_fn = jax.jit(jax.value_and_grad(lambda v, b, k: loss_fn(v, batch=b, key=k), has_aux=True))
    (loss, (m, stats)), g = grad_fn(v, batch, jax.random.key(0))
    assert np.isfinite(float(loss)) and all(np.isfinite(float(x)) for x in m.values())
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree.leaves(g["params"]))
    assert 0 < float(m["div_first"]) <= 1 and 0 < float(m["div_rest"]) <= 1


def test_exp_l1_diversity_by_shifts_equals_the_upper_triangle_of_pairs():
    y = jax.random.normal(jax.random.key(0), (3, 4, 10, 50))
    idx = np.asarray([0, 1, 2, 7, 8, 20, 30, 31, 49])

    def ref(y):
        y = y[..., idx]
        i, j = np.triu_indices(y.shape[-2], 1)
        return jnp.mean(jnp.exp(-jnp.sum(jnp.abs(y[..., i, :] - y[..., j, :]), axis=-1) / 5.0))

    fast = lambda y: gsps._exp_l1_diversity(gsps._take_last(y, idx), 5.0)  # noqa: E731
    np.testing.assert_allclose(fast(y), ref(y), rtol=1e-6)
    np.testing.assert_allclose(jax.grad(fast)(y), jax.grad(ref)(y), rtol=1e-5, atol=1e-9)


@pytest.mark.slow
def test_first_part_once_per_noise_trains_to_the_same_parameters_as_every_sample():
    # The first part's GCN once per first-part noise (nk1 rows per window, BatchNorm counting each nk2
    # times) against once per sample (nk1 * nk2 rows, the release's): the same loss, gradients and
    # BatchNorm statistics, so three Adam steps end at the same parameters and running averages.
    train, _ = _data()
    gen, v0 = _gen(hidden=32)
    prior, pp = _prior()
    pool = gsps.candidate_pool([train[:3000]], 15, 60, 15)
    bounds = jnp.asarray(gsps.measure_angle_bounds(train[::10], ROLES, 0.1))
    rng = np.random.default_rng(0)
    batches = []
    for s in range(3):
        w = pool[rng.integers(0, len(pool), 4)]
        mm, mask = gsps.pseudo_futures(w, pool, rng, t_his=15, his_threshold=0.05, pred_threshold=0.1, num=4)
        batches.append({"window": jnp.asarray(w), "mm": jnp.asarray(mm), "mm_mask": jnp.asarray(mask, jnp.float32)})
    # SGD, not Adam: a graph convolution's bias just before a BatchNorm cancels in it, so its gradient is 0
    # up to rounding, which Adam's normalised step would turn into moves of lr either way in both runs.
    opt = optax.sgd(1e-4)

    def run(once):
        loss_fn = functools.partial(
            gsps.generator_loss, gen, prior=prior, prior_params=pp, t_his=15, parents=PARENTS, parts=PARTS, roles=ROLES,
            angle_bounds=bounds, n_pre=5, nz=8, nk1=3, nk2=4, lambda_his=100.0, lambda_limb=500.0, lambda_div_first=8.0,
            lambda_div_rest=25.0, alpha=100.0, beta=300.0, lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01,
            prior_stride=3, lambda_angle=100.0, first_part_once=once,
        )

        @jax.jit
        def step(v, o, batch, key):
            grad_fn = jax.value_and_grad(lambda p: loss_fn({**v, "params": p}, batch=batch, key=key), has_aux=True)
            (loss, (_, stats)), g = grad_fn(v["params"])
            upd, o = opt.update(g, o, v["params"])
            return {"params": optax.apply_updates(v["params"], upd), "batch_stats": stats}, o, loss, g

        v, o, out = dict(v0), opt.init(v0["params"]), []
        for s, batch in enumerate(batches):
            v, o, loss, g = step(v, o, batch, jax.random.key(s))
            out.append((loss, g))
        return v, out

    v_once, steps_once = run(True)
    v_all, steps_all = run(False)
    for (l1, g1), (l2, g2) in zip(steps_once, steps_all):
        np.testing.assert_allclose(l1, l2, rtol=1e-5)
        scale = max(float(jnp.max(jnp.abs(b))) for b in jax.tree.leaves(g2))
        for a, b in zip(jax.tree.leaves(g1), jax.tree.leaves(g2)):
            np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-5 * scale)
    assert jax.tree.structure(v_once) == jax.tree.structure(v_all)
    for path, a in jax.tree_util.tree_leaves_with_path(v_once):
        b = functools.reduce(lambda t, k: t[k.key], path, v_all)
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6, err_msg=jax.tree_util.keystr(path))
    moved = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(jax.tree.leaves(v_all["params"]), jax.tree.leaves(v0["params"])))
    assert moved > 1e-2  # the steps changed the parameters by far more than the tolerance
    first = v_all["batch_stats"]["part_0"]["gcn"]["gcl_in"]["bn"]["var"]
    assert float(jnp.max(jnp.abs(first - 1.0))) > 1e-3  # the first part's statistics moved (and matched)
    x = batches[0]["window"][:, :15]
    z = gsps.sample_noise(jax.random.key(9), 4, 5, 2, 8)
    seq_once, _ = gsps.generate(gen, v_once, x, z, t_pred=60, n_pre=5, train=False)
    seq_all, _ = gsps.generate(gen, v_all, x, z, t_pred=60, n_pre=5, train=False)
    np.testing.assert_allclose(seq_once, seq_all, atol=1e-5)  # the trained generators predict the same futures


# ----------------------------------------------------------------------------------------------
# The method: stages, predictors, part control.


def test_method_is_registered_with_its_stages_in_order():
    import dataclasses

    from jaxmotion import experiment
    from jaxmotion.config import load_config
    from jaxmotion.methods import get_method

    m = get_method("gsps")
    for path in ("experiments/configs/gsps_synthetic.py", "experiments/configs/gsps_bandai.py"):
        cfg = load_config(path)
        assert cfg.method == "gsps" and isinstance(cfg.method_config, gsps.GSPSConfig)
    ds = make_synthetic(0, train_sequences=1, train_segments=3, test_sequences=1, test_segments=3)
    cfg = dataclasses.replace(load_config("experiments/configs/gsps_synthetic.py"), method_config=gsps.GSPSConfig(num_steps=1))
    st = m.stages(cfg, experiment.prepare(ds))
    assert [s.name for s in st] == ["prior", "angle_bounds", "generator"]
    assert st[2].frozen == ("prior", "angle_bounds") and st[2].batch_norm and st[1].num_steps == 0


TINY_CONFIG = """
from jaxmotion.config import Config
from jaxmotion.models.gsps import GSPSConfig


def get_config():
    return Config(name="tiny", method="gsps", action_metrics=False, eval_k=(3,), max_test_windows=4, ckpt_every=2, log_every=1,
                  method_config=GSPSConfig(prior_batch_size=32, prior_num_steps=2, hidden=8, num_stage=1, nz=4, n_pre=5,
                                           nk1=2, nk2=2, batch_size=2, num_steps=2, mm_candidate_stride=60))
"""


@pytest.mark.slow  # trains a tiny run through the command line (~45 s of CPU, most of it compiling the training steps)
def test_tiny_run_trains_samples_any_k_and_fixes_a_body_part_from_the_command_line(tmp_path, capsys):
    from jaxmotion import cli, experiment
    from jaxmotion.config import load_config
    from jaxmotion.methods import gsps as method

    path, wd = tmp_path / "tiny.py", tmp_path / "run"
    path.write_text(TINY_CONFIG)
    assert cli.main(["train", "--config", str(path), "--workdir", str(wd)]) == 0
    cfg = experiment.resolve(load_config(path))
    prep = experiment.prepare(make_synthetic(0), cfg.max_test_windows)
    ds, params = prep.dataset, experiment.restore(cfg, prep, wd)
    assert set(params) == {"prior", "angle_bounds", "generator"}
    x = jnp.asarray(prep.x[:2])
    for k in (1, 7):
        out = experiment.predictors(cfg, ds, params, k)["gsps"](x, jax.random.key(0))
        assert out.shape == (2, k, 60, 48) and bool(jnp.all(jnp.isfinite(out)))
    c = cfg.method_config
    np.testing.assert_allclose(params["angle_bounds"]["bounds"], gsps.measure_angle_bounds(
        method.bounds_frames(prep.sampler.frames, c.angle_bounds_frames), ROLES, c.angle_percentile, c.angle_margin), atol=1e-6)
    # Evaluation's hooks: metrics under the run's own bounds and prior, and the bounds for metrics.json.
    extra, fields = method.METHOD.extra_metrics(cfg, ds, params)
    m = extra(np.asarray(out), prep.y[:2])
    assert {"angle_violation", "prior_nll", "prior_nll_z", "BDF"} <= set(m) and all(v.shape == (2,) for v in m.values())
    assert fields["angle_bounds"]["bounds"]["Leg2HipPlane_l"] == [
        round(float(b), 4) for b in params["angle_bounds"]["bounds"][gsps.ANGLE_NAMES.index("Leg2HipPlane_l")]]

    lower, upper = gsps.part_coords(PARTS)
    spread = lambda p, c: float(np.max(np.std(p[..., c], axis=-3)))  # noqa: E731  over the K samples
    # `jaxmotion sample --fix-part` (`sample_part_control`): the .npz, the picture and which joints were held.
    argv = ["sample", "--config", str(path), "--workdir", str(wd), "--k", "5"]
    assert cli.main(argv + ["--window", "1", "--fix-part", "lower"]) == 0
    assert "6 of 16 joints identical across the 5 samples: RHip, RKnee, RFoot, LHip, LKnee, LFoot" in capsys.readouterr().out
    p = np.load(wd / "sample_w1_gsps_k5_fix-lower.npz")["preds"]
    assert p.shape == (5, 60, 48) and (wd / "sample_w1_gsps_k5_fix-lower.png").is_file()
    assert spread(p, lower) < 1e-6 < 1e-4 < spread(p, upper)
    y = method.sample_part_control(cfg, ds, params, x, jax.random.key(1), 5, fix=("upper",))
    assert spread(y, lower) > 1e-4  # the legs vary (and the upper body follows them)
    with pytest.raises(ValueError, match="unknown part"):
        method.sample_part_control(cfg, ds, params, x, jax.random.key(1), 5, fix=("legs",))
    with pytest.raises(SystemExit, match="method 'dlow' has no body-part control .*gsps"):
        cli.main(["sample", "--fix-part", "lower"])  # the default config (DLow), refused before any data is read
