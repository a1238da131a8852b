"""BatchNorm with PyTorch's running statistics (`nn.BatchNorm1d`), features last or node-major `(J, ..., F)`.

Both frameworks normalise a training batch by its biased variance. They differ in what they keep
for evaluation: flax's `nn.BatchNorm` averages the biased batch variance into `var`, PyTorch the
unbiased one (times n / (n - 1), n the number of values per feature in the batch: 6.7% at batch
16). Every reference implementation here is PyTorch, so the running variance is PyTorch's. Parameter and statistic names
(`scale`, `bias`; `batch_stats/mean`, `batch_stats/var`) and the momentum convention
(`running = momentum * running + (1 - momentum) * batch`, i.e. PyTorch's momentum 0.1 is 0.9
here) are flax's, so checkpoints of either kind load into the other.

Inside the data-parallel train step the batch moments are the whole global batch's: each device's
moments are averaged over the devices (`batch.batch_mean`, equal shares), as one device
computes them. With `per_device` they are each device's own rows' (no collective; PyTorch
DistributedDataParallel's default), and the train step averages the running statistics.

A batch whose rows come in groups of identical copies (GSPS's first body part, the same for the nk2
samples that share its noise) can be passed one row per group with `repeats`, the group size: equal
copies leave the mean and the biased variance unchanged, so only the count behind the unbiased running
variance changes, and the statistics are those of the full batch.
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn import batch

class BatchNorm(nn.Module):
    """Returns `scale * (x - mean) / sqrt(var + eps) + bias`, statistics per feature over every leading axis."""

    use_running_average: bool
    momentum: float = 0.9
    epsilon: float = 1e-5
    # Node-major input `(J, ..., F)` (nn/gcn.py's GCL stacks): the features are the J * F pairs
    # (j, f), numbered j * F + f as in the flattened `(..., J * F)` layout, so the parameters and
    # statistics are the same arrays in either layout; statistics over the middle axes.
    node_major: bool = False
    # Training moments of each device's rows alone inside the data-parallel step (see the module docstring).
    per_device: bool = False

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "... f"], repeats: int = 1) -> Float[Array, "... f"]:
        """`repeats`: each row of `x` stands for that many equal rows of the batch (see the module docstring)."""
        x = jnp.asarray(x)
        if self.node_major:  # features (J, F) at both ends, statistics over the middle axes
            view = (x.shape[0],) + (1,) * (x.ndim - 2) + (x.shape[-1],)
            axes = tuple(range(1, x.ndim - 1))
        else:  # features last, statistics over every leading axis
            view, axes = (x.shape[-1],), tuple(range(x.ndim - 1))
        f = math.prod(view)  # the parameters and statistics are (f,) vectors, laid over x as `view`
        ra_mean = self.variable("batch_stats", "mean", lambda: jnp.zeros((f,), jnp.float32))
        ra_var = self.variable("batch_stats", "var", lambda: jnp.ones((f,), jnp.float32))
        scale = self.param("scale", nn.initializers.ones_init(), (f,), jnp.float32).reshape(view)
        bias = self.param("bias", nn.initializers.zeros_init(), (f,), jnp.float32).reshape(view)
        if self.use_running_average:
            mean, var = ra_mean.value.reshape(view), ra_var.value.reshape(view)
        else:
            across = (lambda v: v) if self.per_device else batch.batch_mean
            mean = across(jnp.mean(x, axis=axes, keepdims=True))
            var = across(jnp.mean(jnp.square(x - mean), axis=axes, keepdims=True))
            if not self.is_initializing():
                n = math.prod(x.shape[a] for a in axes) * repeats * (1 if self.per_device else batch.batch_parts())
                if self.per_device:
                    batch.note_local_statistics()
                keep = var * (n / (n - 1)) if n > 1 else var  # the unbiased variance
                m = self.momentum
                ra_mean.value = m * ra_mean.value + (1.0 - m) * mean.reshape(-1)
                ra_var.value = m * ra_var.value + (1.0 - m) * keep.reshape(-1)
        return (x - mean) * (scale / jnp.sqrt(var + self.epsilon)) + bias
