"""A GRU decoder loop whose backward pass batches every weight gradient into one product per weight.

The loop is DLow's and MOJO's decoder (`models/cvae.py` `GRUCVAE.decode`): per step t,

    gi = gi_static + [z_t, y_{t-1}] @ W_dyn;  gh = h @ W_hh + b_hh;  h' = gru_update(gi, gh, h)
    a = tanh(... tanh(h' @ K_0 + c_0) ... @ K_n + c_n);  y_t = a @ K_out + c_out (+ y_{t-1} if residual)

Differentiating the `lax.scan` of that step, jax computes each weight's gradient inside the backward
loop, one small product per step and weight (`x_t^T ct_t`, 64 rows at batch 64) plus an add into an
accumulator, for every one of the horizon's steps. Here the backward loop only carries the
activations' cotangents and stacks each product's output cotangent; after the loop each weight's
gradient is one `(T * b, in)^T (T * b, out)` product over the saved inputs. The same numbers up to
float32 summation order (`tests/test_dlow.py`); measured in benchmarks/results/optimisations.md ("Batched weight
gradients of the decoder loop").

float32 only (bf16 takes `decoder_scan`, jax differentiating the same `decoder_step` with its bf16 custom
products) and tanh MLPs only.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from jaxmotion.nn.gru import gru_gates, gru_update, gru_update_backward
from jaxmotion.nn.precision import matmul


def decoder_step(p, gi_static, residual, carry, z_t, precision="float32"):
    """Returns `((h', y_t), (y_t, saved))`: one step of the loop above (`saved`: what the batched backward pass reuses).

    The one definition of the step both backward passes use: `decoder_loop` inverts it by hand,
    `decoder_scan` lets jax differentiate it. `precision`: the products' (nn/precision.py).
    """
    h, y_prev = carry
    dyn = jnp.concatenate([z_t, y_prev], axis=-1)
    gi = gi_static + matmul(dyn, p["w_dyn"], precision)
    gh = matmul(h, p["w_hh"], precision) + p["b_hh"]
    h2 = gru_update(gi, gh, h)
    gates = gru_gates(gi, gh)  # the same products as gru_update's (XLA computes them once)
    acts, a = [], h2
    for k, b in p["mlp"]:
        a = jnp.tanh(matmul(a, k, precision) + b)
        acts.append(a)
    y = matmul(a, p["out"][0], precision) + p["out"][1]
    if residual:
        y = y + y_prev
    return (h2, y), (y, (h, gates, tuple(acts)))  # y_{t-1} is the previous step's y, h' the next step's h


def _rows(x):
    return x.reshape(-1, x.shape[-1])


def _loop_fwd(p, gi_static, h0, y0, z_seq, residual):
    (h_last, _), (ys, saved) = jax.lax.scan(lambda c, z: decoder_step(p, gi_static, residual, c, z), (h0, y0), z_seq)
    return ys, (p, gi_static, h_last, y0, z_seq, ys, saved)


@functools.partial(jax.custom_vjp, nondiff_argnums=(5,))
def _loop(p, gi_static, h0, y0, z_seq, residual):
    return _loop_fwd(p, gi_static, h0, y0, z_seq, residual)[0]  # the unused residuals are dropped by jit


def _shift(first, seq):
    return jnp.concatenate([first[None], seq[:-1]], axis=0)  # the previous step's value at every step


def _loop_bwd(residual, res, ct_ys):
    # The forward pass keeps each step's input state h and its gates (not the pre-activations), so the
    # backward loop reads them as they are: no state shifted by a step, no sigmoid or tanh recomputed.
    # Where only the latents' cotangent is used (a frozen decoder: DLow's and MOJO's Q steps), XLA drops
    # the weight-gradient products after the loop and the per-step outputs that only they read.
    p, gi_static, h_last, y0, z_seq, ys, (h_prev, gates, acts) = res
    nz = z_seq.shape[-1]
    w_dyn_t, w_hh_t = p["w_dyn"].T, p["w_hh"].T
    mlp_t = [k.T for k, _ in p["mlp"]]
    out_t = p["out"][0].T

    def back(carry, xs):
        dh, dy_next, dgi_static = carry
        ct_y, (h, gates, acts) = xs
        dy = ct_y + dy_next  # y_t's whole cotangent: the loss's, and the next step's input's
        da = dy @ out_t
        dpres = [None] * len(acts)
        for i in reversed(range(len(acts))):
            dpres[i] = da * (1.0 - acts[i] ** 2)
            da = dpres[i] @ mlp_t[i]
        dgi, dgh, dh_prev = gru_update_backward(dh + da, gates, h)
        dh_prev = dh_prev + dgh @ w_hh_t
        ddyn = dgi @ w_dyn_t
        dy_prev = ddyn[..., nz:] + dy if residual else ddyn[..., nz:]
        return (dh_prev, dy_prev, dgi_static + dgi), (ddyn[..., :nz], dy, tuple(dpres), dgi, dgh)

    init = (jnp.zeros_like(h_last), jnp.zeros_like(ct_ys[0]), jnp.zeros_like(gi_static))
    xs = (ct_ys, (h_prev, gates, acts))
    (dh0, dy0, dgi_static), (dz, dy, dpres, dgi, dgh) = jax.lax.scan(back, init, xs, reverse=True)
    # Each weight's gradient: one product over all steps and rows.
    grad = lambda x, d: (_rows(x).T @ _rows(d), jnp.sum(_rows(d), axis=0))  # noqa: E731
    h2 = jnp.concatenate([h_prev[1:], h_last[None]], axis=0)  # each step's output state
    dyn = jnp.concatenate([z_seq, _shift(y0, ys)], axis=-1)
    ins = (h2,) + acts[:-1]
    w_hh, b_hh = grad(h_prev, dgh)
    dp = {
        "w_dyn": _rows(dyn).T @ _rows(dgi),
        "w_hh": w_hh,
        "b_hh": b_hh,
        "mlp": [grad(x, d) for x, d in zip(ins, dpres)],
        "out": grad(acts[-1] if acts else h2, dy),
    }
    return dp, dgi_static, dh0, dy0, dz


_loop.defvjp(_loop_fwd, _loop_bwd)


def decoder_loop(params: dict, gi_static, h0, y0, z_seq, *, residual: bool):
    """Returns the decoded frames `(T, b, D)`, time-major, of the loop above.

    `params`: `w_dyn (nz_t + D, 3 nh)` (the GRU input weights of `[z_t, y_{t-1}]`), `w_hh (nh, 3 nh)`,
    `b_hh (3 nh,)`, `mlp` a list of `(kernel, bias)` (tanh after each), `out` `(kernel, bias)`.
    `gi_static (b, 3 nh)`: the input gates' share that does not change over time, bias included.
    `z_seq (T, b, nz_t)`: the per-step latent (`nz_t = 0` for none).
    """
    return _loop(params, gi_static, h0, y0, z_seq, residual)


def decoder_scan(params: dict, gi_static, h0, y0, z_seq, *, residual: bool, precision: str = "float32",
                 remat: bool = True, unroll: int = 1):
    """Returns the same frames as `decoder_loop`, with jax differentiating the `lax.scan` of `decoder_step`.

    Any precision (bf16 products included). `remat`: the step's backward recomputes its elementwise
    work and keeps its products (`jax.checkpoint_policies.dots_saveable`); `unroll`: lax.scan's.
    """
    def step(carry, z_t):
        carry, (y, _) = decoder_step(params, gi_static, residual, carry, z_t, precision)
        return carry, y

    if remat:
        step = jax.checkpoint(step, policy=jax.checkpoint_policies.dots_saveable, prevent_cse=False)
    return jax.lax.scan(step, (h0, y0), z_seq, unroll=unroll)[1]
