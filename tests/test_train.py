"""The training loop: it learns, resumes exactly, refuses to overwrite, and stops on NaN."""

import json

import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxmotion.train.loop import create_state, fit, lr_schedule, make_train_step, restore_params

W_TRUE = np.array([[1.0, -2.0], [0.5, 3.0], [2.0, 0.0]], np.float32)


def _loss(params, frozen, batch, key):
    x, y = batch
    pred = x @ params["w"] + frozen["bias"]
    err = jnp.mean((pred - y) ** 2)
    return err, {"mse": err}


def _sample(rng):
    x = rng.normal(size=(8, 3)).astype(np.float32)
    return x, x @ W_TRUE + 1.0


def _state(tx):
    return create_state({"w": jnp.zeros((3, 2))}, tx, frozen={"bias": jnp.ones(2)})


def test_fit_learns_and_logs(tmp_path):
    tx = optax.adam(0.05)
    state = fit(_state(tx), make_train_step(_loss, tx), _sample, num_steps=300, workdir=tmp_path, seed=0, ckpt_every=100, log_every=50)
    np.testing.assert_allclose(np.asarray(state.params["w"]), W_TRUE, atol=0.05)
    lines = [json.loads(l) for l in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert [l["step"] for l in lines] == [50, 100, 150, 200, 250, 300]
    assert lines[-1]["mse"] < lines[0]["mse"]
    restored = restore_params(tmp_path, _state(tx))
    np.testing.assert_array_equal(np.asarray(restored.params["w"]), np.asarray(state.params["w"]))
    assert int(restored.step) == 300


def test_resume_continues_exactly(tmp_path):
    tx = optax.adam(0.05)
    step = make_train_step(_loss, tx)
    full = fit(_state(tx), step, _sample, num_steps=60, workdir=tmp_path / "a", seed=1, ckpt_every=20)
    fit(_state(tx), step, _sample, num_steps=40, workdir=tmp_path / "b", seed=1, ckpt_every=20)
    resumed = fit(_state(tx), step, _sample, num_steps=60, workdir=tmp_path / "b", seed=1, ckpt_every=20, resume=True)
    np.testing.assert_allclose(np.asarray(resumed.params["w"]), np.asarray(full.params["w"]), rtol=1e-6)


def test_existing_checkpoints_are_not_overwritten(tmp_path):
    tx = optax.adam(0.05)
    fit(_state(tx), make_train_step(_loss, tx), _sample, num_steps=5, workdir=tmp_path, seed=0, ckpt_every=5)
    with pytest.raises(FileExistsError, match="--resume"):
        fit(_state(tx), make_train_step(_loss, tx), _sample, num_steps=5, workdir=tmp_path, seed=0)


def test_non_finite_loss_stops_with_the_step_named(tmp_path):
    tx = optax.sgd(1e30)  # diverges to inf/NaN within a few steps
    with pytest.raises(FloatingPointError, match="non-finite loss .* at step"):
        fit(_state(tx), make_train_step(_loss, tx), _sample, num_steps=200, workdir=tmp_path, seed=0, ckpt_every=10, log_every=10)


def test_missing_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        restore_params(tmp_path, _state(optax.adam(0.1)))


def test_lr_schedule_is_constant_then_linear_to_zero():
    s = lr_schedule(1.0, 100, 0.2)
    assert float(s(0)) == pytest.approx(1.0)
    assert float(s(20)) == pytest.approx(1.0)
    assert float(s(60)) == pytest.approx(0.5)
    assert float(s(100)) == pytest.approx(0.0)


def test_logged_grad_norm_equals_the_global_norm_for_leaves_of_any_rank():
    import jax
    import numpy as np
    import optax

    from jaxmotion.train.loop import _norm

    keys = jax.random.split(jax.random.key(3), 4)
    tree = {"s": jax.random.normal(keys[0], ()), "v": jax.random.normal(keys[1], (7,)),
            "m": {"w": jax.random.normal(keys[2], (300, 129))}, "t": jax.random.normal(keys[3], (2, 3, 5))}
    np.testing.assert_allclose(float(_norm(tree)), float(optax.tree.norm(tree)), rtol=1e-6)
