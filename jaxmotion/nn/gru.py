"""GRU cell with PyTorch's parameterisation, and a `lax.scan` GRU over `(batch, time, dim)`.

We write the cell ourselves rather than use `flax.linen.GRUCell` because the reference
implementations of every method here are PyTorch: identical gates and biases
(`weight_ih`, `weight_hh`, `bias_ih`, `bias_hh`) make weight conversion and parity checks exact.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.precision import matmul


def gru_gates(
    gi: Float[ArrayLike, "b g"], gh: Float[ArrayLike, "b g"]
) -> tuple[Float[Array, "b h"], Float[Array, "b h"], Float[Array, "b h"], Float[Array, "b h"]]:
    """Returns `(r, z, n, h_n)`: the reset, update and new gates, and the hidden share `h_n = W_hn h + b_hn` (PyTorch GRUCell)."""
    i_r, i_z, i_n = jnp.split(gi, 3, axis=-1)
    h_r, h_z, h_n = jnp.split(gh, 3, axis=-1)
    r = jax.nn.sigmoid(i_r + h_r)
    z = jax.nn.sigmoid(i_z + h_z)
    n = jnp.tanh(i_n + r * h_n)
    return r, z, n, h_n


def gru_update(
    gi: Float[ArrayLike, "b g"], gh: Float[ArrayLike, "b g"], h: Float[ArrayLike, "b h"]
) -> Float[Array, "b h"]:
    """Returns `h'` from the input gates `gi = W_i x + b_i` and hidden gates `gh = W_h h + b_h` (PyTorch GRUCell).

    `g = 3 h` (reset, update and new gates); jaxtyping cannot say so here because `h` is bound
    after `gi` and `gh`.

    Split from the matrix products so a caller can compute `gi` outside a time loop: for a whole
    input sequence at once (`GRU`), or once for inputs that do not change over time (a decoder's
    conditioning vector).
    """
    _, z, n, _ = gru_gates(gi, gh)
    return (1.0 - z) * n + z * h


def gru_update_backward(
    dh2: Float[ArrayLike, "b h"], gates: tuple, h: Float[ArrayLike, "b h"]
) -> tuple[Float[Array, "b g"], Float[Array, "b g"], Float[Array, "b h"]]:
    """Returns `(dgi, dgh, dh)`: the cotangents of `gru_update(gi, gh, h)`'s inputs for `dh2`, from its `gru_gates`.

    The chain rule of the equations above, written out so a hand-written backward loop can keep the
    gates of the forward pass instead of the pre-activations (no sigmoid or tanh recomputed); the
    same numbers as `jax.vjp(gru_update, gi, gh, h)` up to float rounding (tests/test_dlow.py).
    """
    r, z, n, h_n = gates
    dn_pre = dh2 * (1.0 - z) * (1.0 - n * n)
    dz_pre = dh2 * (h - n) * z * (1.0 - z)
    dr_pre = dn_pre * h_n * r * (1.0 - r)
    dgi = jnp.concatenate([dr_pre, dz_pre, dn_pre], axis=-1)
    dgh = jnp.concatenate([dr_pre, dz_pre, dn_pre * r], axis=-1)
    return dgi, dgh, dh2 * z


class GRUCell(nn.Module):
    """Returns the next hidden state `h'` (PyTorch `nn.GRUCell` equations).

    r = sigmoid(W_ir x + b_ir + W_hr h + b_hr); z = sigmoid(W_iz x + b_iz + W_hz h + b_hz);
    n = tanh(W_in x + b_in + r * (W_hn h + b_hn)); h' = (1 - z) * n + z * h.
    """

    features: int
    precision: str = "float32"  # the gate products': "float32" or "bf16" (nn/precision.py)

    @nn.compact
    def __call__(self, h: Float[ArrayLike, "b h"], x: Float[ArrayLike, "b i"]) -> Float[Array, "b h"]:
        f = self.features
        bound = 1.0 / jnp.sqrt(f)
        init = lambda shape: (lambda key, s=shape: jax.random.uniform(key, s, jnp.float32, -bound, bound))
        w_ih = self.param("weight_ih", init((x.shape[-1], 3 * f)))
        w_hh = self.param("weight_hh", init((f, 3 * f)))
        b_ih = self.param("bias_ih", init((3 * f,)))
        b_hh = self.param("bias_hh", init((3 * f,)))
        mm = self.precision
        return gru_update(matmul(x, w_ih, mm) + b_ih, matmul(h, w_hh, mm) + b_hh, h)


class GRU(nn.Module):
    """Returns all hidden states `(batch, time, features)` of a GRU run by `lax.scan` over time (parameters `cell/...`).

    With `last_only=True` it returns the last state `(batch, features)` alone: the loop then stacks
    no per-step outputs, and its backward pass adds no (zero) per-step cotangents.
    """

    features: int
    precision: str = "float32"  # as GRUCell.precision
    # lax.scan's `unroll` (>= the sequence length: fully unrolled); the same numbers, faster or not. An
    # int, not True: a module is a jit static argument, and True == 1 would share 1's compiled code.
    unroll: int = 1

    @nn.compact
    def __call__(
        self, x: Float[ArrayLike, "b t i"], h0: Float[ArrayLike, "b h"] | None = None, last_only: bool = False
    ) -> Float[Array, "b t h"] | Float[Array, "b h"]:
        if h0 is None:
            h0 = jnp.zeros(x.shape[:-2] + (self.features,), x.dtype)

        cell = GRUCell(self.features, self.precision, name="cell")
        cell(h0, x[:, 0])  # creates the parameters at init; XLA drops the unused result
        p = cell.variables["params"]
        # The input half of every gate does not depend on h: one (b * t, i) x (i, 3h) product for
        # all steps (as cuDNN / oneDNN GRUs do) leaves only h @ W_hh inside the sequential loop.
        mm = self.precision
        gi = jnp.swapaxes(matmul(x, p["weight_ih"], mm) + p["bias_ih"], 0, 1)

        def step(h, gi_t):
            h = gru_update(gi_t, matmul(h, p["weight_hh"], mm) + p["bias_hh"], h)
            return h, None if last_only else h

        h_last, hs = jax.lax.scan(step, h0, gi, unroll=self.unroll)
        return h_last if last_only else jnp.swapaxes(hs, 0, 1)
