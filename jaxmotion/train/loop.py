"""The one training loop: a pure `train_step(state, batch, key) -> (state, metrics)` jitted once.

Checkpoints are written with orbax every `ckpt_every` steps and at the end; `resume=True`
continues from the latest one. The data stream is a function of `(seed, step)`, so a resumed run
sees exactly the batches an uninterrupted run would have seen. Batches are placed with a
`NamedSharding` over a one-axis device mesh named "data", so the same loop data-parallelises over
several devices; on one device it is a no-op.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
import orbax.checkpoint as ocp
from flax import struct
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from tqdm.auto import tqdm


class TrainState(struct.PyTreeNode):
    """Step counter, trainable `params`, optimiser state, and `frozen` inputs (e.g. a frozen decoder).

    Checkpoints hold everything but `frozen`: frozen inputs are another stage's parameters and are
    checkpointed there.
    """

    step: jax.Array
    params: Any
    opt_state: Any
    frozen: Any = None


# JAX rebuilds a `flax.struct` pytree through `__init__` with whatever leaves a transformation
# carries (None, placeholders), so a check of the fields there is wrong (jaxtyping issue #277, as
# `body.skeleton.SkeletonBody`): `__init__` is opted out of the test suite's import hook.
TrainState.__init__.__no_type_check__ = True


def create_state(params, tx: optax.GradientTransformation, frozen=None) -> TrainState:
    """Returns a fresh `TrainState` at step 0."""
    return TrainState(step=jnp.zeros((), jnp.int32), params=params, opt_state=tx.init(params), frozen=frozen)


def lr_schedule(lr: float, num_steps: int, fix_fraction: float) -> optax.Schedule:
    """Returns DLow's schedule: constant for `fix_fraction` of training, then linear decay to 0."""
    fix = int(num_steps * fix_fraction)
    return optax.join_schedules(
        [optax.constant_schedule(lr), optax.linear_schedule(lr, 0.0, max(num_steps - fix, 1))], [fix]
    )


LossFn = Callable[[Any, Any, Any, jax.Array], tuple[jax.Array, dict]]


def make_train_step(loss_fn: LossFn, tx: optax.GradientTransformation):
    """Returns `train_step(state, batch, key) -> (state, metrics)` for `loss_fn(params, frozen, batch, key)`."""

    def train_step(state: TrainState, batch, key):
        (loss, metrics), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params, state.frozen, batch, key)
        updates, opt_state = tx.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        metrics = dict(metrics, loss=loss, grad_norm=optax.tree.norm(grads))
        return state.replace(step=state.step + 1, params=params, opt_state=opt_state), metrics

    return train_step


# Models with BatchNorm (DivSamp's GCNs, any other): `TrainState.params` is the full variable
# dict `{"params": ..., "batch_stats": ...}`; the optimiser touches only "params".


def bn_optimizer(inner: optax.GradientTransformation) -> optax.GradientTransformation:
    """Returns `inner` on the `"params"` collection and a zero update on `"batch_stats"`."""
    labels = lambda v: {col: jax.tree.map(lambda _: "train" if col == "params" else "stats", sub) for col, sub in v.items()}
    return optax.multi_transform({"train": inner, "stats": optax.set_to_zero()}, labels)


def make_bn_train_step(loss_fn, tx: optax.GradientTransformation):
    """Returns `train_step(state, batch, key) -> (state, metrics)` for a model with BatchNorm.

    `loss_fn(variables, frozen, batch, key) -> (loss, (metrics, new_batch_stats))`; `state.params`
    is the variable dict. As `loop.make_train_step`, plus writing the new statistics.
    """

    def train_step(state: TrainState, batch, key):
        grad_fn = jax.value_and_grad(loss_fn, has_aux=True)
        (loss, (metrics, stats)), grads = grad_fn(state.params, state.frozen, batch, key)
        updates, opt_state = tx.update(grads, state.opt_state, state.params)
        params = dict(optax.apply_updates(state.params, updates), batch_stats=stats)
        metrics = dict(metrics, loss=loss, grad_norm=optax.tree.norm(grads["params"]))
        return state.replace(step=state.step + 1, params=params, opt_state=opt_state), metrics

    return train_step


def data_mesh() -> Mesh:
    """Returns a one-axis mesh named "data" over all local devices."""
    return Mesh(np.array(jax.devices()), ("data",))


def fit(
    state: TrainState,
    train_step,
    sample_batch: Callable[[np.random.Generator], Any],
    *,
    num_steps: int,
    workdir: str | Path,
    seed: int,
    resume: bool = False,
    ckpt_every: int = 500,
    log_every: int = 50,
    desc: str = "train",
) -> TrainState:
    """Returns the trained state after `num_steps` steps, checkpointing into `workdir/ckpt`.

    `sample_batch(rng)` returns one batch (a pytree of numpy arrays whose leading axis is the
    batch); it is called with `np.random.default_rng([seed, step])`. Metrics go to stdout (through
    the progress bar) and to `workdir/log.jsonl`. A non-finite loss stops training with an error
    that names the step; the checkpoints written before it are kept.
    """
    workdir = Path(workdir).absolute()
    workdir.mkdir(parents=True, exist_ok=True)
    mngr = ocp.CheckpointManager(
        workdir / "ckpt",
        options=ocp.CheckpointManagerOptions(max_to_keep=2, save_interval_steps=ckpt_every),
    )
    latest = mngr.latest_step()
    if latest is not None:
        if not resume:
            raise FileExistsError(
                f"{workdir / 'ckpt'} already holds checkpoints (latest step {latest}); "
                "pass --resume to continue from it, or choose another --workdir"
            )
        state = _restore(mngr, latest, state)
    mesh = data_mesh()
    replicated = NamedSharding(mesh, PartitionSpec())
    batch_sharding = NamedSharding(mesh, PartitionSpec("data"))
    # The step donates its state; copy so arrays the caller still holds (a frozen decoder) survive.
    state = jax.device_put(jax.tree.map(jnp.array, state), replicated)
    step_fn = jax.jit(train_step, donate_argnums=0)
    key = jax.random.key(seed)
    start = int(state.step)
    if start >= num_steps:
        if latest is None:  # a stage with nothing to train still leaves its (computed) parameters
            mngr.save(start, args=ocp.args.StandardSave(state.replace(frozen=None)), force=True)
            mngr.wait_until_finished()
        mngr.close()
        return state
    t0 = time.perf_counter()
    with open(workdir / "log.jsonl", "a") as log, tqdm(
        total=num_steps, initial=start, desc=desc, mininterval=2.0, dynamic_ncols=True
    ) as bar:
        for step in range(start, num_steps):
            batch = sample_batch(np.random.default_rng([seed, step]))
            batch = jax.device_put(batch, batch_sharding)
            state, metrics = step_fn(state, batch, jax.random.fold_in(key, step))
            done = step + 1
            if done % log_every == 0 or done == num_steps:
                m = {k: float(v) for k, v in jax.device_get(metrics).items()}
                if not math.isfinite(m["loss"]):
                    mngr.wait_until_finished()
                    raise FloatingPointError(
                        f"{desc}: non-finite loss {m['loss']} at step {done}; "
                        f"last checkpoint: step {mngr.latest_step()} in {workdir / 'ckpt'}"
                    )
                log.write(json.dumps({"stage": desc, "step": done, "time_s": time.perf_counter() - t0, **m}) + "\n")
                log.flush()
                bar.set_postfix({k: f"{v:.4g}" for k, v in m.items() if k in ("loss", "recon", "kld", "div")})
            mngr.save(done, args=ocp.args.StandardSave(state.replace(frozen=None)))
            bar.update(1)
    if mngr.latest_step() != num_steps:
        mngr.save(num_steps, args=ocp.args.StandardSave(state.replace(frozen=None)), force=True)
    mngr.wait_until_finished()
    mngr.close()
    return state


def restore_params(workdir: str | Path, state: TrainState) -> TrainState:
    """Returns the latest checkpointed state in `workdir/ckpt` (`state` gives the structure)."""
    ckpt = Path(workdir).absolute() / "ckpt"
    mngr = ocp.CheckpointManager(ckpt)
    latest = mngr.latest_step()
    if latest is None:
        raise FileNotFoundError(f"no checkpoint in {ckpt}; train first (jaxmotion train / run)")
    restored = _restore(mngr, latest, state)
    mngr.close()
    return restored


def _restore(mngr: ocp.CheckpointManager, step: int, state: TrainState) -> TrainState:
    """Returns checkpoint `step` restored into the structure of `state`, with `state`'s frozen inputs."""
    restored = mngr.restore(step, args=ocp.args.StandardRestore(state.replace(frozen=None)))
    return restored.replace(frozen=state.frozen)
