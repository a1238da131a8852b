"""The one training loop: a pure `train_step(state, batch, key) -> (state, metrics)` jitted once.

Checkpoints are written with orbax every `ckpt_every` steps and at the end (the last two are kept);
`resume=True` continues from the newest one that restores: a truncated or half-written newest
checkpoint is moved to `ckpt.unreadable/` (nothing is deleted) and training resumes from the one
before it, with a warning naming both steps. Each checkpoint carries a checksum of its arrays
(`CHECKSUM`, beside orbax's files); one whose arrays restore to other bytes, or to NaN/inf, is
unreadable too. The data stream is a function of `(seed, step)`, so a
resumed run sees exactly the batches, and logs exactly the lines, an uninterrupted run would have.

The loop data-parallelises over a one-axis device mesh named "data" (`jaxmotion.train.distributed`): every
batch is split over the devices of every process, the state is replicated, and on one device this
is a no-op. With several processes (`jax.distributed`), every process runs `fit` alike: each places
its own rows of the global batch, all of them write the checkpoints together (orbax's multi-host
support), and only process 0 writes the log and shows the progress bar.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
import orbax.checkpoint as ocp
from flax import struct
from jax.flatten_util import ravel_pytree
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from tqdm.auto import tqdm

from jaxmotion.nn import batch as batch_lib
from jaxmotion.train import distributed
from jaxmotion.train.distributed import data_mesh
from jaxmotion.errors import CheckpointError, ConfigError
from jaxmotion.formats.atomic import write_text_atomic


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
    """Returns a fresh `TrainState` at step 0: `params` to train with `tx`, `frozen` (any pytree) passed to the loss as it is."""
    return TrainState(step=jnp.zeros((), jnp.int32), params=params, opt_state=tx.init(params), frozen=frozen)


def lr_schedule(lr: float, num_steps: int, fix_fraction: float) -> optax.Schedule:
    """Returns DLow's schedule: constant for `fix_fraction` of training, then linear decay to 0."""
    fix = int(num_steps * fix_fraction)
    return optax.join_schedules(
        [optax.constant_schedule(lr), optax.linear_schedule(lr, 0.0, max(num_steps - fix, 1))], [fix]
    )


LossFn = Callable[[Any, Any, Any, jax.Array], tuple[jax.Array, dict]]


def make_train_step(loss_fn: LossFn, tx: optax.GradientTransformation, *, mesh: Mesh | None = None, micro_batches: int = 1):
    """Returns `train_step(state, batch, key) -> (state, metrics)` for `loss_fn(params, frozen, batch, key)`.

    Data-parallel over `mesh` (default `distributed.data_mesh()`), one gradient all-reduce per step:
    each device computes its rows' loss and gradient in full, then one `pmean` over the "data" axis
    averages the gradients and metrics (so `loss_fn` must be a mean over the windows of its batch, or
    reduce across windows through `distributed.batch_sum` / `batch_mean`). With `micro_batches` m > 1
    each device's rows are taken in m consecutive micro-batches, their gradients summed in a scan and
    divided by m before the one reduction (gradient accumulation: the global batch's gradient with a
    device holding the activations of only one micro-batch). The batch size must be a multiple of
    the device count times m.

    Args:
        loss_fn: `loss_fn(params, frozen, batch, key) -> (scalar loss, {name: scalar})`, a mean over
            the windows of `batch`; `frozen` is `TrainState.frozen` (e.g. a trained CVAE's parameters).
        tx: the optax optimiser; `create_state(params, tx, frozen)` makes the matching state.
        mesh: the devices (default: every device on one "data" axis).
        micro_batches: m, for gradient accumulation.

    Returns:
        `train_step(state, batch, key) -> (state, metrics)`, jitted: `batch` is `(B, t_his + t_pred, D)`
            windows (or any array whose leading axis is the batch), `key` a `jax.random` key, `metrics`
            the device-averaged `{name: scalar}` of `loss_fn` with "loss" and "grad_norm" added.
    """
    return _data_parallel_step(_grads(loss_fn, batch_norm=False), tx, mesh, micro_batches, batch_norm=False)


# Models with BatchNorm (DivSamp's GCNs, any other): `TrainState.params` is the full variable
# dict `{"params": ..., "batch_stats": ...}`; the optimiser touches only "params".


def bn_optimizer(inner: optax.GradientTransformation) -> optax.GradientTransformation:
    """Returns `inner` on the `"params"` collection and a zero update on `"batch_stats"`."""
    labels = lambda v: {col: jax.tree.map(lambda _: "train" if col == "params" else "stats", sub) for col, sub in v.items()}
    return optax.multi_transform({"train": inner, "stats": optax.set_to_zero()}, labels)


def make_bn_train_step(loss_fn, tx: optax.GradientTransformation, *, mesh: Mesh | None = None, micro_batches: int = 1):
    """Returns `train_step(state, batch, key) -> (state, metrics)` for a model with BatchNorm.

    `loss_fn(variables, frozen, batch, key) -> (loss, (metrics, new_batch_stats))`; `state.params`
    is the variable dict. As `make_train_step`, plus writing the new statistics. BatchNorm's batch
    moments are those of the whole global batch (`nn.batchnorm.BatchNorm` averages them over the
    devices); with micro-batches they are each micro-batch's, and the running statistics follow the
    micro-batches in turn.
    """
    return _data_parallel_step(_grads(loss_fn, batch_norm=True), tx, mesh, micro_batches, batch_norm=True)


def _grads(loss_fn, *, batch_norm: bool):
    """Returns `grads(params, frozen, batch, key) -> (loss, metrics, grads, new batch_stats or None)` of one device's rows."""
    if not batch_norm:
        def grads(params, frozen, batch, key):
            (loss, metrics), g = jax.value_and_grad(loss_fn, has_aux=True)(params, frozen, batch, key)
            return loss, metrics, g, None
    else:  # the gradient of the statistics is zero (the loss normalises by the batch's moments), bn_optimizer ignores it
        def grads(variables, frozen, batch, key):
            (loss, (metrics, stats)), g = jax.value_and_grad(loss_fn, has_aux=True)(variables, frozen, batch, key)
            return loss, metrics, g, stats
    return grads


def _data_parallel_step(grads, tx, mesh: Mesh | None, micro_batches: int, *, batch_norm: bool):
    mesh = data_mesh() if mesh is None else mesh
    n, m = mesh.shape[distributed.DATA], int(micro_batches)
    if m < 1:
        raise ValueError(f"micro_batches must be >= 1, got {micro_batches}")

    def local(state: TrainState, batch, key):  # one device's rows of the batch
        device = jax.lax.axis_index(distributed.DATA) if n > 1 else 0
        with batch_lib.local_statistics() as local_stats:
            if m == 1:
                with distributed.batch_part(device, n):
                    loss, metrics, g, stats = grads(state.params, state.frozen, batch, key)
            else:
                loss, metrics, g, stats = _accumulate(grads, state, batch, key, device, n, m, batch_norm)
        if n > 1:  # the step's one all-reduce, of one array: between processes each collective costs a round trip
            if local_stats:  # per-device BatchNorm moments: each device's running statistics differ, average them too
                flat, unravel = ravel_pytree((loss, metrics, g, stats))
                loss, metrics, g, stats = unravel(jax.lax.pmean(flat, distributed.DATA))
            else:
                flat, unravel = ravel_pytree((loss, metrics, g))
                loss, metrics, g = unravel(jax.lax.pmean(flat, distributed.DATA))
        updates, opt_state = tx.update(g, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        if batch_norm:
            params = dict(params, batch_stats=stats)
        metrics = dict(metrics, loss=loss, grad_norm=_norm(g["params"] if batch_norm else g))
        return state.replace(step=state.step + 1, params=params, opt_state=opt_state), metrics

    if n == 1:  # one device: the step itself, the program a step without a mesh compiles to
        return local
    # Unchecked replication: the outputs are equal on every device because they come from the pmean.
    spec = PartitionSpec(distributed.DATA)
    return jax.shard_map(local, mesh=mesh, in_specs=(PartitionSpec(), spec, PartitionSpec()),
                         out_specs=(PartitionSpec(), PartitionSpec()), check_vma=False)


def _norm(tree) -> jax.Array:
    """Returns the global L2 norm of `tree` (the logged `grad_norm`), each leaf's squares summed row by row first.

    As one whole-leaf sum, XLA:CPU wrote the squares of DivSamp's 73 MB bases gradient out unfused and then summed
    them (5.6 and 8.3 ms of a 278 ms step in the profile, `benchmarks/results/optimisations.md`); summed row by row,
    the HumanEva-I sampler step went 0.295 -> 0.282 s, alternating rounds in one run
    (`benchmarks/results/grad_norm_rows_ab.json`). The parameters and updates do not read it; the value differs from
    one whole-leaf sum at float rounding only."""
    def sq(a):
        a = a.reshape(a.shape[0], -1) if a.ndim > 1 else a.reshape(1, -1)
        return jnp.sum(jnp.sum(jnp.square(a), axis=1))
    return jnp.sqrt(sum(sq(a) for a in jax.tree.leaves(tree)))


def _accumulate(grads, state: TrainState, batch, key, device, n: int, m: int, batch_norm: bool):
    """Returns `(loss, metrics, grads, batch_stats)` of a device's rows as the mean over `m` consecutive micro-batches."""
    micro = jax.tree.map(lambda a: a.reshape((m, a.shape[0] // m) + a.shape[1:]), batch)

    def one(j, b, params):
        with distributed.batch_part(device * m + j, n * m):
            return grads(params, state.frozen, b, key)

    def body(carry, xs):
        total, params = carry
        loss, metrics, g, stats = one(xs[0], xs[1], params)
        total = jax.tree.map(jnp.add, total, (loss, metrics, g))
        return (total, dict(params, batch_stats=stats) if batch_norm else params), None

    loss, metrics, g, stats = one(0, jax.tree.map(lambda a: a[0], micro), state.params)
    params = dict(state.params, batch_stats=stats) if batch_norm else state.params
    rest = (jnp.arange(1, m), jax.tree.map(lambda a: a[1:], micro))
    (total, params), _ = jax.lax.scan(body, ((loss, metrics, g), params), rest)
    loss, metrics, g = jax.tree.map(lambda t: t / m, total)
    return loss, metrics, g, params["batch_stats"] if batch_norm else None


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
    evaluate: Callable[[Any], dict | None] | None = None,
    eval_every: int = 0,
    mesh: Mesh | None = None,
    micro_batches: int = 1,
) -> TrainState:
    """Returns the trained state after `num_steps` steps, checkpointing into `workdir/ckpt`.

    `sample_batch(rng)` returns one batch (a pytree of numpy arrays whose leading axis is the
    batch); it is called with `np.random.default_rng([seed, step])`. Metrics go to stdout (through
    the progress bar) and to `workdir/log.jsonl`; on resume, lines past the restored step (written
    before a kill) move to `log.replaced.jsonl`, as the resumed run writes them again. A non-finite
    loss stops training with an error that names the step; the checkpoints written before it are
    kept. A checkpoint that cannot be written (read-only folder, full disk) is a `CheckpointError`
    naming the folder and the step kept.

    With `evaluate(params) -> dict | None` and `eval_every > 0`, a learning-curve point is logged
    before the first step, every `eval_every` steps and at the end: a log line `{"stage", "step",
    "curve": true, "eval_s", **evaluate(state.params)}` (nothing when it returns None). `time_s`
    of the training lines excludes the time spent in those evaluations.

    Each batch is split over the devices of `mesh` (default `distributed.data_mesh()`: every device of
    every process), so its size must be a multiple of their number (`ConfigError` otherwise, before
    the first step), times `micro_batches` when `train_step` accumulates over micro-batches
    (`make_train_step`, made for the same mesh). With several processes every one of them calls `fit` with the same arguments and
    draws the same global batches; `evaluate` runs in all of them, only process 0 logs.
    """
    workdir = Path(workdir).absolute()
    workdir.mkdir(parents=True, exist_ok=True)
    ckpt = workdir / "ckpt"
    mngr = _manager(ckpt, ckpt_every)
    latest = mngr.latest_step()
    if latest is not None:
        if not resume:
            raise FileExistsError(
                f"{ckpt} already holds checkpoints (latest step {latest}); "
                "pass --resume to continue from it, or choose another --workdir"
            )
        restored, step, bad = _restore_newest(ckpt, mngr.all_steps(), state)
        if restored is None:
            mngr.close()
            raise CheckpointError(
                f"{ckpt}: no checkpoint restores (" + "; ".join(f"step {s}: {e}" for s, e in bad) + "); nothing "
                f"was deleted: move {ckpt} away to train this stage from scratch"
            )
        if bad:
            mngr.close()
            aside = _unreadable(ckpt)
            if distributed.is_main():
                _move_aside(ckpt, [s for s, _ in bad])
            distributed.barrier(f"move aside {ckpt}")
            warnings.warn(
                f"{ckpt}: checkpoint step {bad[0][0]} is unreadable ({bad[0][1]}); resuming from step {step}, the newest "
                f"that restores; moved the unreadable checkpoint(s) to {aside} (nothing deleted)",
                stacklevel=2,
            )
            mngr = _manager(ckpt, ckpt_every)
        state = restored
        if distributed.is_main():
            _replace_log_after(workdir / "log.jsonl", step)
    mesh = data_mesh() if mesh is None else mesh
    replicated = NamedSharding(mesh, PartitionSpec())
    batch_sharding = NamedSharding(mesh, PartitionSpec("data"))
    # The step donates its state; copy so arrays the caller still holds (a frozen decoder) survive.
    state = distributed.replicate(state, replicated)
    step_fn = jax.jit(train_step, donate_argnums=0)
    key = jax.random.key(seed)
    start = int(state.step)
    if start >= num_steps:
        if latest is None:  # a stage with nothing to train still leaves its (computed) parameters
            _save(mngr, ckpt, start, state, force=True, wait=True)
        mngr.close()
        return state
    t0 = time.perf_counter()
    curve_s = 0.0

    def curve_point(log, done):
        nonlocal curve_s
        t = time.perf_counter()
        m = evaluate(state.params)
        dt = time.perf_counter() - t
        curve_s += dt
        if m is not None:
            log.write(json.dumps({"stage": desc, "step": done, "curve": True, "eval_s": round(dt, 3), **m}) + "\n")
            log.flush()

    curves = evaluate is not None and eval_every > 0
    main = distributed.is_main()
    with open(workdir / "log.jsonl" if main else os.devnull, "a") as log, tqdm(
        total=num_steps, initial=start, desc=desc, mininterval=2.0, dynamic_ncols=True, disable=not main
    ) as bar:
        if curves and start == 0:
            curve_point(log, 0)
        for step in range(start, num_steps):
            batch = sample_batch(np.random.default_rng([seed, step]))
            if step == start:
                distributed.check_batch(batch, mesh, f"stage {desc!r}", micro_batches)
            batch = distributed.global_batch(batch, batch_sharding)
            state, metrics = step_fn(state, batch, jax.random.fold_in(key, step))
            done = step + 1
            if done % log_every == 0 or done == num_steps:
                try:
                    m = {k: float(v) for k, v in jax.device_get(metrics).items()}
                except jax.errors.JaxRuntimeError as e:
                    _raise_if_out_of_memory(e, workdir)
                    raise
                if not math.isfinite(m["loss"]):
                    _save(mngr, ckpt, None, None, wait=True)
                    raise FloatingPointError(
                        f"{desc}: non-finite loss {m['loss']} at step {done}; "
                        f"last checkpoint: step {mngr.latest_step()} in {workdir / 'ckpt'}"
                    )
                log.write(json.dumps({"stage": desc, "step": done, "time_s": time.perf_counter() - t0 - curve_s, **m}) + "\n")
                log.flush()
                bar.set_postfix({k: f"{v:.4g}" for k, v in m.items() if k in ("loss", "recon", "kld", "div")})
            if curves and (done % eval_every == 0 or done == num_steps):
                curve_point(log, done)
            _save(mngr, ckpt, done, state)
            bar.update(1)
    if mngr.latest_step() != num_steps:
        _save(mngr, ckpt, num_steps, state, force=True)
    _save(mngr, ckpt, None, None, wait=True)
    mngr.close()
    return state


def _manager(ckpt: Path, ckpt_every: int = 1) -> ocp.CheckpointManager:
    # Synchronous writes: a failed asynchronous one (read-only folder, full disk) is reported only at the
    # next save, and leaves orbax threads that keep the process from exiting for up to 10 minutes.
    options = ocp.CheckpointManagerOptions(max_to_keep=2, save_interval_steps=ckpt_every, enable_async_checkpointing=False)
    return ocp.CheckpointManager(ckpt, options=options)


def _save(mngr: ocp.CheckpointManager, ckpt: Path, step: int | None, state: TrainState | None, *, force=False, wait=False):
    """Saves `state` as checkpoint `step` (None: only waits), raising `CheckpointError` naming the folder on failure.

    Orbax writes into a temporary folder and renames it when complete, so a failed or killed write
    leaves the checkpoints before it as they were.
    """
    try:
        if step is not None:
            saved = mngr.save(step, args=ocp.args.StandardSave(state.replace(frozen=None)), force=force)
            if saved and distributed.is_main():
                mngr.wait_until_finished()
                write_text_atomic(ckpt / str(step) / CHECKSUM, json.dumps({"sha256": tree_digest(state.replace(frozen=None))}))
        if wait:
            mngr.wait_until_finished()
    except Exception as e:
        with contextlib.suppress(Exception):  # its background writer would otherwise keep the process alive
            mngr.close()
        _raise_if_out_of_memory(e, ckpt.parent)  # a step's failed allocation surfaces where the state is first read
        kept = sorted(int(p.name) for p in ckpt.iterdir() if p.name.isdigit()) if ckpt.is_dir() else []
        raise CheckpointError(
            f"{ckpt}: cannot write checkpoint{'' if step is None else f' step {step}'} ({_brief(e)}); "
            f"the checkpoints kept there: steps {kept}"
        ) from e


def _raise_if_out_of_memory(e: Exception, stage_dir: Path) -> None:
    """Raises `ConfigError` when `e` is XLA failing to allocate: the config asks for more memory than there is."""
    if "RESOURCE_EXHAUSTED: Out of memory" in str(e):
        raise ConfigError(str(stage_dir), [f"a training step ran out of memory ({_brief(e)}); lower the batch size or the "
                                           "layer widths (jaxmotion.config.memory_estimate gives a lower bound)"]) from None


CHECKSUM = "jaxmotion_checksum.json"  # in each step folder: {"sha256": tree_digest(the saved state)}


def tree_digest(tree) -> str:
    """Returns a SHA-256 of the arrays of `tree` (dtype, shape, bytes), independent of the tree's structure.

    Independent of the structure, so a checkpoint restored without a target (a dict, not a `TrainState`)
    has the digest of the state that was saved: the sorted digests of the leaves, hashed.
    """
    leaves = []
    for leaf in jax.tree.leaves(tree):
        a = np.asarray(leaf.addressable_data(0) if isinstance(leaf, jax.Array) else leaf)  # replicated: one copy
        leaves.append(hashlib.sha256(f"{a.dtype.str}{a.shape}".encode() + np.ascontiguousarray(a).tobytes()).hexdigest())
    return hashlib.sha256("".join(sorted(leaves)).encode()).hexdigest()


class CorruptCheckpoint(CheckpointError):
    """A checkpoint that restores, but not to what was saved: what is wrong, without the folder."""


def verify_restored(ckpt: Path, step: int, tree) -> None:
    """Raises `CorruptCheckpoint` when checkpoint `step`'s restored arrays differ from its checksum or hold NaN/inf.

    Orbax restores flipped bytes inside array data without complaint; the checksum written with the
    checkpoint catches them. A checkpoint without one (written before checksums, or killed between
    orbax's write and the checksum's) is checked for non-finite values only.
    """
    for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]:
        a = np.asarray(leaf.addressable_data(0) if isinstance(leaf, jax.Array) else leaf)
        if np.issubdtype(a.dtype, np.inexact) and not np.isfinite(a).all():
            raise CorruptCheckpoint(f"it restores non-finite values (NaN/inf) in {jax.tree_util.keystr(path)}")
    file = ckpt / str(step) / CHECKSUM
    if file.is_file():
        try:
            want = json.loads(file.read_text())["sha256"]
        except (ValueError, KeyError, TypeError) as e:
            raise CorruptCheckpoint(f"its checksum file {CHECKSUM} is unreadable ({_brief(e)})") from e
        if tree_digest(tree) != want:
            raise CorruptCheckpoint("its arrays restore to other bytes than were saved (checksum mismatch: corrupted on disk)")


def _brief(e: BaseException) -> str:
    if isinstance(e, CorruptCheckpoint):
        return str(e)
    first = (str(e).strip().splitlines() or [""])[0]
    return f"{type(e).__name__}: {first[:240]}"


def _restore_newest(ckpt: Path, steps, state: TrainState):
    """Returns `(state, step, bad)`: the newest checkpoint in `ckpt` that restores (None, None if none does)
    and the `(step, error)` of the newer ones that did not."""
    bad = []
    for step in sorted(steps, reverse=True):
        # A manager per attempt: one that failed on a broken step folder also fails on the good ones.
        mngr = ocp.CheckpointManager(ckpt)
        try:
            restored = _restore(mngr, step, state)
            if int(restored.step) != step:
                raise CheckpointError(f"it holds step {int(restored.step)}")
            return restored, step, bad
        except Exception as e:  # truncated files, a missing _METADATA, zeroed data: whatever orbax raises
            bad.append((step, _brief(e)))
        finally:
            mngr.close()
    return None, None, bad


def _unreadable(ckpt: Path) -> Path:
    return ckpt.with_name(ckpt.name + ".unreadable")


def _move_aside(ckpt: Path, steps: list[int]) -> Path:
    """Moves the step folders `steps` of `ckpt` into `ckpt.unreadable/` (renamed, never deleted); returns that folder."""
    aside = _unreadable(ckpt)
    aside.mkdir(exist_ok=True)
    for s in steps:
        target, n = aside / str(s), 1
        while target.exists():
            target, n = aside / f"{s}-{n}", n + 1
        os.replace(ckpt / str(s), target)
    return aside


def _replace_log_after(log: Path, step: int) -> None:
    """Moves the log lines of steps after `step` (and a line cut by a kill) to `log.replaced.jsonl`."""
    if not log.is_file():
        return
    keep, replaced = [], []
    for line in log.read_text().splitlines(keepends=True):
        try:
            ok = line.endswith("\n") and json.loads(line)["step"] <= step
        except (ValueError, KeyError, TypeError):
            ok = False
        (keep if ok else replaced).append(line)
    if replaced:
        with open(log.with_name("log.replaced.jsonl"), "a") as f:
            f.write("".join(line if line.endswith("\n") else line + "\n" for line in replaced))
        write_text_atomic(log, "".join(keep))


def restore_params(workdir: str | Path, state: TrainState) -> TrainState:
    """Returns the latest checkpointed state in `workdir/ckpt` (`state` gives the structure).

    Raises `CheckpointError` naming the step when it does not restore (unreadable, or another structure).
    """
    ckpt = Path(workdir).absolute() / "ckpt"
    mngr = ocp.CheckpointManager(ckpt)
    latest = mngr.latest_step()
    if latest is None:
        raise FileNotFoundError(f"no checkpoint in {ckpt}; train first (jaxmotion train / run)")
    try:
        restored = _restore(mngr, latest, state)
    except Exception as e:
        raise CheckpointError(f"{ckpt}: checkpoint step {latest} does not restore ({_brief(e)})") from e
    finally:
        mngr.close()
    return restored


def local_sharding() -> jax.sharding.Sharding:
    """Returns the sharding of an array on this process's first device (where a one-process restore puts arrays)."""
    return jax.sharding.SingleDeviceSharding(jax.local_devices()[0])


def restore_untargeted(ckpt: str | Path) -> tuple[int, Any]:
    """Returns `(step, tree)`: the latest checkpoint in `ckpt` restored without a target structure.

    An array is restored with the sharding it was saved with when this process has those devices, else
    onto this process's first device (`local_sharding`): a run trained on several processes (or on more
    devices) loads in one process, where orbax alone refuses it ("Topology mismatch", its checkpoint
    naming devices this process does not have). Raises `CheckpointError` when there is no checkpoint or
    it does not restore.
    """
    ckpt = Path(ckpt).absolute()
    mngr = ocp.CheckpointManager(ckpt)
    step = None
    try:
        step = mngr.latest_step()
        if step is None:
            raise CheckpointError(f"{ckpt}: no checkpoint; train this run first (jaxmotion train)")
        tree = mngr.restore(step, args=ocp.args.StandardRestore(fallback_sharding=local_sharding()))
        verify_restored(ckpt, step, tree)
        return step, tree
    except CorruptCheckpoint as e:
        raise CheckpointError(f"{ckpt}: checkpoint step {step} is unreadable: {e}") from e
    except CheckpointError:
        raise
    except Exception as e:
        if step is None:
            raise CheckpointError(f"{ckpt}: checkpoints do not list ({_brief(e)})") from e
        raise CheckpointError(f"{ckpt}: checkpoint step {step} is unreadable: {_brief(e)}") from e
    finally:
        mngr.close()


def _restore(mngr: ocp.CheckpointManager, step: int, state: TrainState) -> TrainState:
    """Returns checkpoint `step` restored into the structure of `state`, with `state`'s frozen inputs."""
    restored = mngr.restore(step, args=ocp.args.StandardRestore(state.replace(frozen=None)))
    verify_restored(Path(mngr.directory), step, restored)
    return restored.replace(frozen=state.frozen)
