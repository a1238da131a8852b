"""GSPS: the pose prior (exact inverse, log-det, density of valid poses), angle limits, the generator and its objective."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

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
    params = prior.init(jax.random.key(seed), jnp.zeros((1, dim)))
    # Push the PReLU slopes away from their init so both branches matter.
    return prior, params


def test_prior_inverse_inverts():
    prior, params = _prior()
    d = jax.random.normal(jax.random.key(1), (64, 48))
    z, _ = prior.apply(params, d)
    back = prior.apply(params, z, method=gsps.PosePrior.inverse)
    np.testing.assert_allclose(back, d, atol=2e-4)
    assert float(jnp.mean(z < 0)) > 0.2  # the PReLU's negative branch was exercised


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
    return np.arccos(np.sum(t * s, -1) / np.linalg.norm(t, axis=-1) / np.linalg.norm(s, axis=-1))


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
