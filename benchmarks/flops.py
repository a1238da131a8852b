"""How many floating-point operations a jitted function does: XLA's cost analysis, with its loops counted in full.

XLA's `compiled.cost_analysis()["flops"]` counts the body of a `while` loop once, whatever its trip
count, so for the recurrent models (a `lax.scan` over 60 frames) it reports a small fraction of
the work. `count` therefore also asks XLA's cost analysis about the same function with every
`lax.scan` fully unrolled (its jaxpr rewritten with `unroll = length`, then lowered), and counts
the matrix products (`dot_general`, convolutions) from the jaxpr, each scan body times its length.
`run.py` prints the three side by side with a hand count for one case, and uses the unrolled
figure for the roofline.
"""

from __future__ import annotations

import math

import jax
from jax.extend import core as jcore


def _map_jaxprs(value, fn):
    """Returns `value` with `fn` applied to every (closed) jaxpr in it (a parameter of an equation)."""
    if isinstance(value, jcore.ClosedJaxpr):
        return value.replace(jaxpr=fn(value.jaxpr))
    if isinstance(value, jcore.Jaxpr):
        return fn(value)
    if isinstance(value, tuple) and any(isinstance(v, (jcore.ClosedJaxpr, jcore.Jaxpr)) for v in value):
        return tuple(_map_jaxprs(v, fn) for v in value)
    return value


def unroll_scans(jaxpr: jcore.Jaxpr) -> jcore.Jaxpr:
    """Returns `jaxpr` with every `scan` (nested ones too) set to unroll fully, so that XLA sees no loop."""
    eqns = []
    for eqn in jaxpr.eqns:
        params = {k: _map_jaxprs(v, unroll_scans) for k, v in eqn.params.items()}
        if eqn.primitive.name == "scan":
            params["unroll"] = max(1, params["length"])
        eqns.append(eqn.replace(params=params))
    return jaxpr.replace(eqns=eqns)


def _sub_jaxprs(value):
    if isinstance(value, jcore.ClosedJaxpr):
        yield value.jaxpr
    elif isinstance(value, jcore.Jaxpr):
        yield value
    elif isinstance(value, tuple):
        for v in value:
            yield from _sub_jaxprs(v)


def matmul_flops(jaxpr: jcore.Jaxpr) -> int:
    """Returns 2 x the multiply-adds of every matrix product and convolution in `jaxpr`, loops counted in full.

    A scan body counts `length` times, a `cond` its costliest branch, a `while` body once (its trip
    count is not known from the jaxpr).
    """
    total = 0
    for eqn in jaxpr.eqns:
        name = eqn.primitive.name
        out = eqn.outvars[0].aval.shape if eqn.outvars else ()
        if name == "dot_general":
            (contract, _), _ = eqn.params["dimension_numbers"]
            lhs = eqn.invars[0].aval.shape
            total += 2 * math.prod(out) * math.prod(lhs[i] for i in contract)
        elif name == "conv_general_dilated":
            rhs = eqn.invars[1].aval.shape
            out_features = rhs[eqn.params["dimension_numbers"].rhs_spec[0]]
            total += 2 * math.prod(out) * math.prod(rhs) // out_features
        subs = [matmul_flops(j) for v in eqn.params.values() for j in _sub_jaxprs(v)]
        if subs:
            if name == "cond":
                total += max(subs)
            else:
                total += sum(subs) * (eqn.params["length"] if name == "scan" else 1)
    return total


def count(fn, *args) -> dict:
    """Returns `{"flops", "matmul_flops"}` of `fn(*args)`: XLA's cost analysis with scans unrolled, and the products alone.

    Dead code (e.g. a layer applied only to create its parameters, which XLA drops) is removed first.
    """
    closed = jax.make_jaxpr(fn)(*args)
    # Internal, but the one dead-code pass jax has; keeps every input, so `args` still fit.
    from jax._src.interpreters.partial_eval import dce_jaxpr

    closed = closed.replace(jaxpr=dce_jaxpr(closed.jaxpr, True, instantiate=True)[0])
    unrolled = closed.replace(jaxpr=unroll_scans(closed.jaxpr))
    flat = jax.tree.leaves(args)
    cost = jax.jit(jcore.jaxpr_as_fun(unrolled)).lower(*flat).cost_analysis()
    return {"flops": float(cost["flops"]), "matmul_flops": float(matmul_flops(closed.jaxpr))}


def dlow_prior_hand_count(cvae, t_his: int, k: int) -> int:
    """Returns the matrix-product FLOPs of `dlow.sample_prior` for one window and K futures, counted by hand.

    `cvae` is the `DLowCVAE` (its sizes: D, t_pred = horizon, nh_rnn, nz, nh_mlp). Per window: the past
    encoder GRU, `t_his` steps of input and hidden gate products (3 nh gates), and the decoder's
    start `drnn_mlp(h_x)` (nh -> nh_mlp -> nh). Per future: the loop-invariant share of the GRU
    input gates `[h_x, z] @ W_ih[:nh + nz]` once, then per step `y_prev @ W_ih[nh + nz:]`,
    `h @ W_hh`, the MLP nh -> nh_mlp and the output layer to D (`GRUCVAE.decode`).
    """
    mm = lambda n_in, n_out: 2 * n_in * n_out  # noqa: E731  (one row times an n_in x n_out matrix)
    d, nh, nz, g = cvae.dim, cvae.nh_rnn, cvae.nz, 3 * cvae.nh_rnn
    widths = (nh, *cvae.nh_mlp)
    mlp = sum(mm(a, b) for a, b in zip(widths[:-1], widths[1:]))
    encoder = t_his * (mm(d, g) + mm(nh, g))
    start = mlp + mm(widths[-1], nh)
    step = mm(d, g) + mm(nh, g) + mlp + mm(widths[-1], d)
    return encoder + start + k * (mm(nh + nz, g) + cvae.horizon * step)
