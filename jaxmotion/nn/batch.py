"""The batch axis inside the train step: helpers a loss or a layer uses across the windows of a batch.

The train step (`train.loop.make_train_step`) runs each device's share of the global batch as its
own program (`jax.shard_map` over the mesh axis `DATA`); a loss inside it sees only its device's
rows. What a loss computes across windows goes through these helpers, which are the identity
outside the step: `batch_rows` for a random draw with a batch axis (the rows of the global draw,
so every run draws what one device draws), `batch_mean` / `batch_sum` for a statistic over the
whole batch (BatchNorm's moments, a ratio of sums). A loss that is a mean over windows needs none
of them. Starting processes, the mesh and global batches are `jaxmotion.train.distributed`'s.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator

import jax

DATA = "data"  # the mesh axis the batch is split over

# While the train step is traced: `(index, count)`, the part of the global batch (in `count` equal,
# consecutive parts) that the loss being traced sees; None elsewhere. Set only by `batch_part`.
_PART: contextvars.ContextVar = contextvars.ContextVar("jaxmotion_batch_part", default=None)


@contextlib.contextmanager
def batch_part(index: jax.Array | int, count: int) -> Iterator[None]:
    """Traces the code inside as the loss of part `index` (an integer, traced or not) of `count` equal parts of the global batch.

    The train step sets it around each device's (and each micro-batch's) loss; `batch_rows` reads it.
    """
    token = _PART.set((index, int(count)))
    try:
        yield
    finally:
        _PART.reset(token)


def batch_rows(draw: Callable[[int], jax.Array], b: int) -> jax.Array:
    """Returns `draw(b)`, a random draw whose leading axis is the `b` windows of the batch the caller sees.

    Inside the train step (`batch_part`), where the caller sees part i of n equal parts of the
    global batch, it is rows `i * b ... (i + 1) * b` of `draw(n * b)`: a run draws the numbers one
    device draws for the whole batch, on any number of devices or micro-batches.
    """
    part = _PART.get()
    if part is None or part[1] == 1:
        return draw(b)
    index, count = part
    return jax.lax.dynamic_slice_in_dim(draw(b * count), index * b, b, axis=0)


# While the train step is traced: a list that a BatchNorm with per-device moments appends to, so the
# step averages the running statistics it returns; None elsewhere. Set only by `local_statistics`.
_LOCAL: contextvars.ContextVar = contextvars.ContextVar("jaxmotion_local_statistics", default=None)


@contextlib.contextmanager
def local_statistics() -> Iterator[list]:
    """Traces the code inside, returning a list that is non-empty when a layer kept statistics of its device's rows alone."""
    seen: list = []
    token = _LOCAL.set(seen)
    try:
        yield seen
    finally:
        _LOCAL.reset(token)


def note_local_statistics() -> None:
    """Records, for the train step being traced, that a layer's statistics are its device's own (`local_statistics`)."""
    seen = _LOCAL.get()
    if seen is not None and _in_step():
        seen.append(True)


def _in_step() -> bool:
    return DATA in jax.sharding.get_abstract_mesh().manual_axes


def batch_sum(x):
    """Returns the sum of `x` over the devices' parts of the batch inside the train step (`x` elsewhere)."""
    return jax.lax.psum(x, DATA) if _in_step() else x


def batch_mean(x):
    """Returns the mean of `x` over the devices' parts of the batch inside the train step (`x` elsewhere)."""
    return jax.lax.pmean(x, DATA) if _in_step() else x


def batch_parts() -> int:
    """Returns how many devices share the batch inside the train step (1 elsewhere)."""
    return jax.sharding.get_abstract_mesh().shape[DATA] if _in_step() else 1
