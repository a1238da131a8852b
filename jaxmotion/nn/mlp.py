"""Multi-layer perceptron as used by DLow: a nonlinearity after every layer."""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.linear import Dense


class MLP(nn.Module):
    """Returns `act(Dense(...act(Dense(x))))`: DLow's MLP (tanh after every layer)."""

    features: tuple[int, ...]
    activation: str = "tanh"  # any jax.nn name, or "tanh"
    dense_init: str = "torch"  # "torch" (PyTorch nn.Linear) or "flax" (nn.Dense); see nn/linear.py
    precision: str = "float32"  # the products': "float32" or "bf16" (nn/precision.py)

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "... i"]) -> Float[Array, "... o"]:
        act = getattr(jax.nn, self.activation) if self.activation != "tanh" else jnp.tanh
        for i, f in enumerate(self.features):
            x = act(Dense(f, rule=self.dense_init, precision=self.precision, name=f"dense_{i}")(x))
        return x
