"""Many devices and many processes: starting `jax.distributed`, the "data" mesh, global batches.

JAX runs one program per process (one process per host, or per GPU), each addressing its own
devices; a computation over arrays that span every process's devices runs on all of them at once
(docs/pages/distributed.md). jaxmotion data-parallelises over a one-axis mesh named "data"
over every device of every process: the batch is split along its leading axis, parameters and
optimiser state are replicated. The train step (`train.loop.make_train_step`) is written per device
(`jax.shard_map` over "data"): each device computes the gradient of its rows' loss in full, then one
`pmean` of the gradient tree and the metrics makes them the global batch's, so there is one
all-reduce per step whatever the sequence length (a step left to XLA's partitioner reduces the
recurrent weights' gradients inside the backward scans, one collective per time step).

Inside that step a loss sees only its device's rows, so what a loss computes across windows goes
through the helpers of `jaxmotion.nn.batch` (importable from here too), which are the identity outside the step: `batch_rows` for a random draw
with a batch axis (the rows of the global draw, so every run draws what one device draws),
`batch_mean` / `batch_sum` for a statistic over the whole batch (BatchNorm's moments, a ratio of
sums). A loss that is a mean over windows needs none of them.

Every process draws the whole global batch from `(seed, step)` and hands its own devices their rows
(`global_batch`), so process p's shard is a function of `(seed, step, p)` and the batches, hence the
run, are those of one process on one device with the same global batch, up to the order of float
sums. Only process 0 writes files (`is_main`).
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding

from jaxmotion.errors import ConfigError
# The batch-axis helpers a loss uses live with the networks (`jaxmotion.nn.batch`): a model imports them from there.
from jaxmotion.nn.batch import DATA, batch_mean, batch_part, batch_parts, batch_rows, batch_sum  # noqa: F401


# The settings of `jax.distributed.initialize`, and the environment variables that give them when no
# flag does. JAX itself reads only JAX_COORDINATOR_ADDRESS; the other two are read here.
ENV = {"coordinator_address": "JAX_COORDINATOR_ADDRESS", "num_processes": "JAX_NUM_PROCESSES", "process_id": "JAX_PROCESS_ID"}


def initialize(
    coordinator_address: str | None = None, num_processes: int | None = None, process_id: int | None = None, *, auto: bool = False
) -> bool:
    """Returns whether `jax.distributed` runs, after starting it when a setting is given or `auto` (a no-op otherwise).

    A setting that is None comes from its environment variable (`ENV`), then from JAX's detection of
    the cluster (SLURM, Open MPI, Cloud TPU, Kubernetes): `auto=True` with no setting at all starts
    it from that detection alone. Must run before any JAX computation; a second call does nothing.
    """
    if jax.distributed.is_initialized():
        return True
    given = {"coordinator_address": coordinator_address, "num_processes": num_processes, "process_id": process_id}
    settings = {k: v if v is not None else os.environ.get(ENV[k]) or None for k, v in given.items()}
    if not auto and all(v is None for v in settings.values()):
        return False
    problems = []
    for k in ("num_processes", "process_id"):
        v = settings[k]
        if isinstance(v, str):
            try:
                settings[k] = int(v)
            except ValueError:
                problems.append(f"{ENV[k]}={v!r}: {k} must be an integer")
    n, i, addr = settings["num_processes"], settings["process_id"], settings["coordinator_address"]
    if isinstance(n, int) and n < 1:
        problems.append(f"num_processes must be >= 1, got {n}")
    if isinstance(i, int) and (i < 0 or (isinstance(n, int) and i >= n)):
        problems.append(f"process_id must be in [0, num_processes{f' = {n}' if isinstance(n, int) else ''}), got {i}")
    if addr is not None and not addr.rpartition(":")[2].isdigit():
        problems.append(f"coordinator_address must be HOST:PORT (the address of process 0), got {addr!r}")
    if problems:
        raise ConfigError("jax.distributed settings", problems)
    try:
        jax.distributed.initialize(addr, n, i)
    except ValueError as e:  # a setting neither given nor detected: JAX names it
        raise ConfigError("jax.distributed settings", [
            f"{e} No cluster (SLURM, Open MPI, Cloud TPU) gave it: pass --coordinator-address HOST:PORT, "
            f"--num-processes N and --process-id I, or set {', '.join(ENV.values())}"
        ]) from e
    return True


def is_main() -> bool:
    """Returns whether this is process 0, the one that writes logs, metrics, pictures and progress bars."""
    return jax.process_index() == 0


def barrier(name: str) -> None:
    """Waits until every process reaches the barrier `name` (nothing to wait for with one process)."""
    if jax.process_count() > 1:
        multihost_utils.sync_global_devices(name)


def data_mesh() -> Mesh:
    """Returns a one-axis mesh named "data" over every device of every process."""
    return Mesh(np.array(jax.devices()), (DATA,))


def check_batch(batch, mesh: Mesh, what: str, micro_batches: int = 1) -> None:
    """Raises `ConfigError` naming `what`, the batch size and the device count when the batch does not split evenly.

    Each device takes an equal share of every batch, in `micro_batches` equal micro-batches.
    """
    parts = mesh.size * micro_batches
    over = f"{mesh.size} devices" + (f" x {micro_batches} micro-batches" if micro_batches > 1 else "")
    sizes = sorted({int(np.shape(a)[0]) for a in jax.tree.leaves(batch)})
    bad = [b for b in sizes if b % parts]
    if bad:
        raise ConfigError(what, [
            f"batch size {bad[0]} does not split over {over} (each device takes an equal share of every "
            f"batch{', in equal micro-batches' if micro_batches > 1 else ''}): choose a batch size that is a multiple of "
            f"{parts}, or run on a number of devices that divides {bad[0]}"
            + (" (or fewer micro_batches)" if micro_batches > 1 else "")
        ])


def process_rows(sharding: NamedSharding, n: int) -> np.ndarray:
    """Returns the indices of the rows of an `(n, ...)` array batch-sharded by `sharding` that this process's devices hold."""
    starts = sorted({idx[0].start or 0 for idx in sharding.addressable_devices_indices_map((n,)).values()})
    per = n // sharding.mesh.size
    return np.concatenate([np.arange(s, s + per) for s in starts])


def global_batch(batch, sharding: NamedSharding):
    """Returns the global batch as arrays sharded by `sharding`, each process giving only its own rows of `batch`.

    `batch` is the whole global batch (a pytree of numpy arrays, leading axis the batch), the same in
    every process.
    """

    def place(a):
        a = np.asarray(a)
        return jax.make_array_from_process_local_data(sharding, a[process_rows(sharding, a.shape[0])], a.shape)

    return jax.tree.map(place, batch)


def replicate(tree, sharding: NamedSharding):
    """Returns a copy of `tree` on every device of `sharding` (which replicates); the caller's arrays stay valid."""
    if jax.process_count() == 1:
        return jax.device_put(jax.tree.map(jnp.array, tree), sharding)
    # No process can send to another's devices: each places its own copy of the (equal) values.
    return jax.tree.map(lambda a: jax.make_array_from_process_local_data(sharding, np.asarray(a), np.shape(a)), tree)


def gather(x: jax.Array) -> np.ndarray:
    """Returns the whole of `x` (its global shape) as numpy in every process (an all-gather when it spans several processes)."""
    if x.is_fully_addressable:
        return np.asarray(x)
    return np.asarray(multihost_utils.process_allgather(x, tiled=True))
