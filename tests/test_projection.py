"""Recursive projection: decoder step -> body fit -> fitted markers fed back, in one jitted scan over K."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.body.projection import body_fit_fn, project_k, recursive_projection
from jaxmotion.body.skeleton import toy_skeleton

BODY = toy_skeleton("cmu41")
M = BODY.num_markers
# One stage (it frees global and body parameters) keeps the compile short.
FIT = body_fit_fn(BODY, stages=("body",), lambda_pose=0.0, max_steps=40)


def valid_frame(seed: int, pose_std: float = 0.2):
    p = BODY.zero_params()
    p = p._replace(pose=pose_std * jax.random.normal(jax.random.key(seed), p.pose.shape))
    return p, BODY.markers(p).reshape(-1)


@pytest.mark.slow
def test_stand_in_decoder_feeds_back_the_fitted_frame_and_valid_bodies_are_fixed_points():
    init, y0 = valid_frame(0)
    k, t = 3, 4
    velocity = jnp.tile(jnp.array([0.01, 0.0, 0.02]), M)  # a translation keeps the body valid

    def step(carry, noise):
        (y_prev,) = carry
        y = y_prev + velocity + noise
        return (y,), y

    noise = 0.01 * jax.random.normal(jax.random.key(1), (k, t, 3 * M))
    noise = noise.at[0].set(0.0)  # sample 0: the decoder only ever outputs valid bodies
    carry0 = (jnp.broadcast_to(y0, (k, 3 * M)),)
    out = jax.jit(lambda c, n: project_k(step, FIT, c, n, init))(carry0, noise)
    assert out.raw.shape == out.markers.shape == (k, t, 3 * M)
    assert out.params.pose.shape == (k, t, init.pose.shape[0]) and out.residual.shape == (k, t, M)
    # Fed back: each raw frame starts from the previous fitted frame, not from the raw one.
    np.testing.assert_allclose(out.raw[:, 1:], out.markers[:, :-1] + velocity + noise[:, 1:], atol=1e-5)
    # A valid body is a fixed point (within 1 mm); noisy frames are moved onto the body.
    assert float(out.residual[0].max()) < 1e-3
    assert float(out.residual[1:].mean()) > 3e-3


@pytest.mark.slow
def test_mojo_decode_step_runs_inside_the_projection_scan_batched_over_k():
    from jaxmotion.models import mojo

    cfg = mojo.MojoConfig(nz=4, nh_rnn=8, nh_mlp=(8,))
    t_his, t_pred, k = 3, 4, 2
    model = mojo.cvae_model(cfg, 3 * M, t_pred)
    init, y0 = valid_frame(2)
    x = jnp.broadcast_to(y0, (k, t_his, 3 * M))
    variables = model.init(jax.random.key(0), x, jnp.broadcast_to(y0, (k, t_pred, 3 * M)))
    dparams = mojo.decoder_params(model, variables)
    z = jax.random.normal(jax.random.key(3), (k, model.n_bands, cfg.nz))
    init_k = jax.tree.map(lambda a: jnp.broadcast_to(a, (k,) + a.shape), init)

    @jax.jit
    def run(x, z):
        carry0, inputs = mojo.decode_inputs(dparams, x, z)
        step = lambda c, i: mojo.decode_step(dparams, c, i)  # noqa: E731
        return recursive_projection(step, FIT, carry0, inputs, init_k), carry0, inputs

    out, carry0, inputs = run(x, z)
    assert out.raw.shape == (t_pred, k, 3 * M) and out.params.pose.shape[:2] == (t_pred, k)
    assert np.all(np.isfinite(np.asarray(out.markers)))
    # Step 2 of the scan is MOJO's decoder started from the fitted frame of step 1.
    c1, y1 = mojo.decode_step(dparams, carry0, jax.tree.map(lambda a: a[0], inputs))
    c1 = c1._replace(y_prev=out.markers[0])
    _, y2 = mojo.decode_step(dparams, c1, jax.tree.map(lambda a: a[1], inputs))
    np.testing.assert_allclose(out.raw[0], y1, atol=1e-5)
    np.testing.assert_allclose(out.raw[1], y2, atol=1e-4)
