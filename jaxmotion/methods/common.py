"""Pieces the method files share: the zero-velocity baseline, the training-window batch source, DLow's optimiser, the execution."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion.nn.execution import Execution
from jaxmotion.train.loop import lr_schedule


def zero_velocity(t_pred: int, k: int):
    """Returns a predictor that repeats the last observed pose: the zero-velocity baseline."""
    return jax.jit(lambda x, key: jnp.broadcast_to(x[:, None, -1:], (x.shape[0], k, t_pred, x.shape[-1])))


def window_batches(prep, batch_size: int) -> Callable[[np.random.Generator], np.ndarray]:
    """Returns `rng -> (batch_size, t_total, D)` random training windows ([protocol §4][datasets])."""
    return lambda rng: prep.sampler.sample(rng, batch_size)


def adam(lr: float, num_steps: int, lr_fix_fraction: float) -> optax.GradientTransformation:
    """Returns Adam with DLow's schedule (constant for `lr_fix_fraction` of training, then linear to 0)."""
    return optax.adam(lr_schedule(lr, num_steps, lr_fix_fraction))


def execution_of(cfg) -> Execution:
    """Returns how a run's networks execute (nn/execution.py): the config's `precision` and `batch_norm`, every other choice the default."""
    return Execution(precision=cfg.precision, batch_norm=cfg.batch_norm)
