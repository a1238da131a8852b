"""The networks' matrix products in float32, or in bfloat16 with float32 accumulation (`Config.precision`).

"float32" (the default) is the plain `x @ w` of every layer. "bf16" rounds both operands of each weight product to bfloat16 (8 bits of
mantissa) and accumulates the sum in float32 (`preferred_element_type`), the products' result staying
float32; parameters, optimiser state, activations, nonlinearities, BatchNorm, losses and metrics stay
float32. On a CPU with bfloat16 instructions (`avx512_bf16`, `amx_bf16`) XLA's bfloat16 products run
at up to about twice the float32 rate (measured peaks: docs/pages/benchmarks.md); on a CPU
without them they are emulated and slower. Layers whose numbers are sensitive to rounding keep
float32 whatever the option: GSPS's flow prior (its log-determinant and exact inverse), the metrics
and the action classifier behind CMD / FID.

Layers take the choice as a module attribute (`precision`), a static part of the module, so a jitted
function traced with one choice is never reused for the other; a model reads it from its
`Execution` (nn/execution.py).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.execution import PRECISIONS


def check(precision: str, what: str = "precision") -> str:
    """Returns `precision` when it is one of `PRECISIONS`, else raises ValueError naming `what`."""
    if precision not in PRECISIONS:
        raise ValueError(f"{what} must be one of {PRECISIONS}, got {precision!r}")
    return precision


_BF16, _F32 = jnp.bfloat16, jnp.float32


def _dot(a, b, dims):
    return jax.lax.dot_general(a, b, dims, preferred_element_type=_F32)


def _last_first(x_ndim: int):
    return (((x_ndim - 1,), (0,)), ((), ()))


# The gradients' products in bfloat16 too. Differentiating the plain bfloat16 product would up-cast
# its operands and compute both backward products in float32 (jax's transpose rule follows the
# float32 cotangent), adding conversions and saving nothing; here the backward pass rounds the
# cotangent to bfloat16 and keeps the forward pass's bfloat16 operands as residuals (half the memory).
@jax.custom_vjp
def _matmul_bf16(x, w):
    return _dot(x.astype(_BF16), w.astype(_BF16), _last_first(x.ndim))


def _matmul_bf16_fwd(x, w):
    xb, wb = x.astype(_BF16), w.astype(_BF16)
    return _dot(xb, wb, _last_first(x.ndim)), (xb, wb)


def _matmul_bf16_bwd(res, ct):
    xb, wb = res
    cb = ct.astype(_BF16)
    dx = _dot(cb, wb, (((ct.ndim - 1,), (1,)), ((), ())))  # ct @ w.T: (..., i)
    lead = tuple(range(ct.ndim - 1))
    dw = _dot(xb, cb, ((lead, lead), ((), ())))  # sum over the leading axes of x^T ct: (i, o)
    return dx, dw


_matmul_bf16.defvjp(_matmul_bf16_fwd, _matmul_bf16_bwd)


@jax.custom_vjp
def _graph_bf16(a, h):
    return jnp.einsum("ij,...jo->...io", a.astype(_BF16), h.astype(_BF16), preferred_element_type=_F32)


def _graph_bf16_fwd(a, h):
    ab, hb = a.astype(_BF16), h.astype(_BF16)
    return jnp.einsum("ij,...jo->...io", ab, hb, preferred_element_type=_F32), (ab, hb)


def _graph_bf16_bwd(res, ct):
    ab, hb = res
    cb = ct.astype(_BF16)
    da = jnp.einsum("...io,...jo->ij", cb, hb, preferred_element_type=_F32)
    dh = jnp.einsum("ij,...io->...jo", ab, cb, preferred_element_type=_F32)
    return da, dh


_graph_bf16.defvjp(_graph_bf16_fwd, _graph_bf16_bwd)


def matmul(x: Float[ArrayLike, "... i"], w: Float[ArrayLike, "i o"], precision: str = "float32") -> Float[Array, "... o"]:
    """Returns `x @ w` (`w` 2-D): in float32, or with bfloat16 operands and float32 accumulation.

    `x` of more than two axes is multiplied as the 2-D `(rows, i)` view of itself. The result is the
    same, but the weight gradient `x^T ct` is then a 2-D product: from a 3-D `x`, jax's transpose rule
    contracts two leading axes, and XLA:CPU canonicalises that dot by copying the cotangent into a
    transposed layout first (one 1.3 MB copy per GCN layer in DivSamp's CVAE step). Measured A/B in
    one process (benchmarks/results/optimisations.md, "Weight products on 2-D views"): DivSamp's CVAE step 1.15x-1.22x,
    GSPS's generator step 1.14x, DLow's Q step 1.13x faster, the other cases unchanged.
    """
    x = jnp.asarray(x)
    if x.ndim > 2:
        return matmul(x.reshape(-1, x.shape[-1]), w, precision).reshape(x.shape[:-1] + (jnp.shape(w)[-1],))
    if precision == "float32":
        return x @ w
    check(precision)
    return _matmul_bf16(jnp.asarray(x, _F32), jnp.asarray(w, _F32))


def graph_matmul(a: Float[ArrayLike, "j j"], h: Float[ArrayLike, "... j o"], precision: str = "float32") -> Float[Array, "... j o"]:
    """Returns `A H` per leading index, `einsum("ij,...jo->...io")` (a graph convolution's adjacency product)."""
    if precision == "float32":
        return jnp.einsum("ij,...jo->...io", a, h)
    check(precision)
    return _graph_bf16(jnp.asarray(a, _F32), jnp.asarray(h, _F32))


# The node-major adjacency product `A H` with H laid out (J, ..., F), for GraphConv(node_major=True).
# Its gradient `dA = ct @ H^T` contracts the two operands over their last axis, rest = batch x
# features long. For long contractions XLA:CPU's YNNPACK kernel for that transposed-operand shape
# is slow: (20, 409600) x (20, 409600) took 20.0-22.1 ms in five of six separate runs (one 7.9) on
# the 2-core AMD EPYC (32 MiB L3). Contracting over H's middle and last axes as two dimensions
# makes XLA transpose H into (rest, J) first and run the plain form: 8.4-9.1 ms. Below ~300k the
# transposed-operand form is the faster one (16k: 0.15 vs 0.27 ms; 205k: 2.8-3.6 vs 4.2-4.3 ms),
# and DivSamp's CVAE step (16k) was 5% slower with the two-axis form, so it is used from
# `NODE_GRAD_TWO_AXIS_MIN` on (GSPS's generator at the release's sizes: 409,600). dH = A^T ct is
# written to come out node-major. benchmarks/results/optimisations.md, "The adjacency gradient", has the A/B.
# bfloat16 keeps the 2-D product (`_matmul_bf16`): XLA:CPU has no bf16 x bf16 -> f32 kernel for the
# multi-axis forms (DotThunk: UNIMPLEMENTED).
NODE_GRAD_TWO_AXIS_MIN = 2**18


@jax.custom_vjp
def _node_f32(a, h):
    return jax.lax.dot_general(a, h, (((1,), (0,)), ((), ())))


def _node_f32_fwd(a, h):
    return _node_f32(a, h), (a, h)


def _node_f32_bwd(res, ct):
    a, h = res
    j = h.shape[0]
    if h.shape[1] * h.shape[2] >= NODE_GRAD_TWO_AXIS_MIN:
        da = jax.lax.dot_general(ct, h, (((1, 2), (1, 2)), ((), ())))
    else:
        da = jax.lax.dot_general(ct.reshape(j, -1), h.reshape(j, -1), (((1,), (1,)), ((), ())))
    dh = jax.lax.dot_general(a, ct, (((0,), (0,)), ((), ())))  # (J, M, F)
    return da, dh


_node_f32.defvjp(_node_f32_fwd, _node_f32_bwd)


def node_matmul(a: Float[ArrayLike, "j j"], h: Float[ArrayLike, "j *rest f"], precision: str = "float32") -> Float[Array, "j *rest f"]:
    """Returns `A H` for node-major H `(J, ..., F)`, `einsum("ij,j...->i...")`, its gradient in the fast product shape.

    "float32": the operands' own dtype (float64 under `jax_enable_x64` stays float64), the same
    numbers as the plain product but for the order of summation; "bf16": as `matmul`.
    """
    h = jnp.asarray(h)
    j = h.shape[0]
    if check(precision) == "bf16":
        return _matmul_bf16(jnp.asarray(a, _F32), jnp.asarray(h, _F32).reshape(j, -1)).reshape(h.shape)
    dtype = jnp.result_type(a, h)
    out = _node_f32(jnp.asarray(a, dtype), jnp.asarray(h, dtype).reshape(j, -1, h.shape[-1]))
    return out.reshape(h.shape)
