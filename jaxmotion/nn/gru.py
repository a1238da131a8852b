"""GRU cell with PyTorch's parameterisation, and a `lax.scan` GRU over `(batch, time, dim)`.

We write the cell ourselves rather than use `flax.linen.GRUCell` because the reference
implementations of every method here are PyTorch: identical gates and biases
(`weight_ih`, `weight_hh`, `bias_ih`, `bias_hh`) make weight conversion and parity checks exact.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


class GRUCell(nn.Module):
    """Returns the next hidden state `h'` (PyTorch `nn.GRUCell` equations).

    r = sigmoid(W_ir x + b_ir + W_hr h + b_hr); z = sigmoid(W_iz x + b_iz + W_hz h + b_hz);
    n = tanh(W_in x + b_in + r * (W_hn h + b_hn)); h' = (1 - z) * n + z * h.
    """

    features: int

    @nn.compact
    def __call__(self, h: Float[Array, "b h"], x: Float[Array, "b i"]) -> Float[Array, "b h"]:
        f = self.features
        bound = 1.0 / jnp.sqrt(f)
        init = lambda shape: (lambda key, s=shape: jax.random.uniform(key, s, jnp.float32, -bound, bound))
        w_ih = self.param("weight_ih", init((x.shape[-1], 3 * f)))
        w_hh = self.param("weight_hh", init((f, 3 * f)))
        b_ih = self.param("bias_ih", init((3 * f,)))
        b_hh = self.param("bias_hh", init((3 * f,)))
        gi = x @ w_ih + b_ih
        gh = h @ w_hh + b_hh
        i_r, i_z, i_n = jnp.split(gi, 3, axis=-1)
        h_r, h_z, h_n = jnp.split(gh, 3, axis=-1)
        r = jax.nn.sigmoid(i_r + h_r)
        z = jax.nn.sigmoid(i_z + h_z)
        n = jnp.tanh(i_n + r * h_n)
        return (1.0 - z) * n + z * h


class GRU(nn.Module):
    """Returns all hidden states `(batch, time, features)` of a GRU run by `lax.scan` over time."""

    features: int

    @nn.compact
    def __call__(self, x: Float[Array, "b t i"], h0: Float[Array, "b h"] | None = None) -> Float[Array, "b t h"]:
        if h0 is None:
            h0 = jnp.zeros(x.shape[:-2] + (self.features,), x.dtype)

        def step(cell, h, x_t):
            h = cell(h, x_t)
            return h, h

        scan = nn.scan(step, variable_broadcast="params", split_rngs={"params": False}, in_axes=1, out_axes=1)
        _, hs = scan(GRUCell(self.features, name="cell"), h0, x)
        return hs
