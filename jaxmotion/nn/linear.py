"""A dense layer whose initialisation is a named choice: PyTorch's `nn.Linear` rule or flax's default.

The reference implementations of every method here are PyTorch, where `nn.Linear` draws weights
and biases from U(-1/sqrt(fan_in), 1/sqrt(fan_in)) (`kaiming_uniform_(a=sqrt(5))` on the weight,
the same bound on the bias). flax's `nn.Dense` draws lecun-normal weights, N(0, 1/fan_in) truncated,
and zero biases: a weight standard deviation sqrt(3) larger. That difference changes what a CVAE
learns in a short budget (DLow's CVAE KL at step 50 on Bandai-Namco-2: 132 nats with flax's rule,
7.8 with PyTorch's; the release: 4.7). "torch" is the default and every model's; `Dense(rule="flax")`
is bit-for-bit flax's `nn.Dense` (same parameter names, same random draws).
"""

from __future__ import annotations

import math

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.precision import matmul

DENSE_INITS = ("torch", "flax")


def torch_uniform(fan_in: int) -> nn.initializers.Initializer:
    # PyTorch's nn.Conv2d uses the same rule with fan_in = in_channels * prod(kernel size).
    """Returns an initialiser drawing from U(-1/sqrt(fan_in), 1/sqrt(fan_in)) (PyTorch `nn.Linear`, weight and bias)."""
    bound = 1.0 / math.sqrt(fan_in)
    return lambda key, shape, dtype=jnp.float32: jax.random.uniform(key, shape, dtype, -bound, bound)


def initializers(rule: str, fan_in: int, what: str = "Dense.rule") -> tuple[nn.initializers.Initializer, nn.initializers.Initializer]:
    """Returns `(weight_init, bias_init)` of `rule` for a layer with `fan_in` inputs (dense or convolution)."""
    if rule == "torch":
        return torch_uniform(fan_in), torch_uniform(fan_in)
    if rule == "flax":
        return nn.initializers.lecun_normal(), nn.initializers.zeros_init()
    raise ValueError(f"{what} must be one of {DENSE_INITS}, got {rule!r}")


class Dense(nn.Module):
    """Returns `x @ kernel + bias`, initialised by `rule`: "torch" (PyTorch `nn.Linear`) or "flax" (`nn.Dense`)."""

    features: int
    rule: str = "torch"
    precision: str = "float32"  # the product's: "float32" or "bf16" (nn/precision.py)

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "... i"]) -> Float[Array, "... o"]:
        fan_in = x.shape[-1]
        k_init, b_init = initializers(self.rule, fan_in)
        kernel = self.param("kernel", k_init, (fan_in, self.features), jnp.float32)
        bias = self.param("bias", b_init, (self.features,), jnp.float32)
        if self.precision == "float32" and x.ndim <= 2:
            return jax.lax.dot_general(x, kernel, (((x.ndim - 1,), (0,)), ((), ()))) + bias
        return matmul(x, kernel, self.precision) + bias  # many axes: as a 2-D product (nn/precision.py)


class Conv1x1(nn.Module):
    """Returns a 1 x 1 convolution of channels-last `x`, `x @ kernel[0, 0] + bias`, initialised by `rule` (fan_in = input channels).

    The parameters are laid out as `nn.Conv((1, 1))`'s (`kernel` `(1, 1, in, out)`, `bias` `(out,)`),
    so weights convert to and from PyTorch's `nn.Conv2d(in, out, 1)` by a transpose. It is computed as
    one `(pixels, in) x (in, out)` product rather than a convolution: with MotionMap's 8 channels on a
    128 x 128 map XLA:CPU's convolution and its filter gradient made the whole heatmap network's
    gradient 1.9x slower (measured with another run sharing the cores; the quiet A/B of the heatmap
    step is in benchmarks/results/optimisations.md, "MotionMap's heatmap stage").
    """

    features: int
    rule: str = "torch"

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "... c"]) -> Float[Array, "... o"]:
        c = x.shape[-1]
        k_init, b_init = initializers(self.rule, c)
        kernel = self.param("kernel", k_init, (1, 1, c, self.features), jnp.float32)
        bias = self.param("bias", b_init, (self.features,), jnp.float32)
        # Flattened to 2-D first: a dot over one long row axis, whose kernel gradient XLA forms as one
        # (in, pixels) x (pixels, out) product (on the 4-D array it was a slow reduction).
        y = jnp.reshape(x, (-1, c)) @ kernel[0, 0] + bias
        return y.reshape(x.shape[:-1] + (self.features,))
