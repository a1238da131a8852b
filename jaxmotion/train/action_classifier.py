"""Training the action classifier of `jaxmotion.models.action_classifier` (FID's features) with the one train step."""

from __future__ import annotations

import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.sharding import Mesh

from jaxmotion.train import distributed
from jaxmotion.models.action_classifier import ActionClassifier, ClassifierConfig, make_model
from jaxmotion.train.loop import create_state, make_train_step


def loss_fn(model: ActionClassifier):
    """Returns `loss(params, frozen, batch, key) -> (cross-entropy, {"acc"})` for `loop.make_train_step`."""

    def loss(params, frozen, batch, key):
        y, labels = batch
        logits, _ = model.apply(params, y)
        ce = optax.softmax_cross_entropy_with_integer_labels(logits, labels).mean()
        return ce, {"acc": jnp.mean(jnp.argmax(logits, -1) == labels)}

    return loss


def train(
    sample_batch: Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]],
    num_classes: int,
    c: ClassifierConfig,
    *,
    log: Callable[[str], None] | None = print,
    log_every: int = 250,
    name: str = "action classifier",
) -> dict:
    """Returns the trained parameters after `c.num_steps` Adam steps of cross-entropy.

    `sample_batch(rng) -> (futures (b, t, D), labels (b,) int)` is called with
    `np.random.default_rng([c.seed, step])`, so the run is a function of `c` and the data alone.
    Progress (loss, batch accuracy, seconds) goes to `log` every `log_every` steps.
    """
    if num_classes < 2:
        raise ValueError(f"{name}: needs at least 2 classes, got {num_classes}")
    model = make_model(num_classes, c)
    y0, _ = sample_batch(np.random.default_rng([c.seed, 0]))
    # One frame gives the parameters of any length; jitted, init is one compile instead of one per operation.
    params = jax.jit(model.init)(jax.random.key(c.seed), jnp.asarray(y0[:1, :1]))
    tx = optax.adam(optax.cosine_decay_schedule(c.lr, c.num_steps, alpha=0.05))
    # Every process trains the same classifier on its first device (the batches are its local arrays).
    one = Mesh(np.array(jax.local_devices()[:1]), (distributed.DATA,))
    step_fn = jax.jit(make_train_step(loss_fn(model), tx, mesh=one), donate_argnums=0)
    state = jax.jit(lambda p: create_state(p, tx))(params)  # one compile, not one per optimiser leaf
    key, t0 = jax.random.key(c.seed), time.perf_counter()
    for step in range(c.num_steps):
        y, labels = sample_batch(np.random.default_rng([c.seed, step]))
        state, m = step_fn(state, (jnp.asarray(y), jnp.asarray(labels, jnp.int32)), jax.random.fold_in(key, step))
        done = step + 1
        if log is not None and (done % log_every == 0 or done == c.num_steps):
            loss, acc = float(m["loss"]), float(m["acc"])
            if not np.isfinite(loss):
                raise FloatingPointError(f"{name}: non-finite loss {loss} at step {done}")
            log(f"{name}: step {done}/{c.num_steps} loss {loss:.4f} batch accuracy {acc:.3f} ({time.perf_counter() - t0:.0f} s)")
    return state.params
