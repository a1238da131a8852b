"""The networks' matrix products in float32, or in bfloat16 with float32 accumulation (`Config.precision`).

"float32" (the default) is the plain `x @ w` of every layer, bit for bit what the library computed
before this option existed. "bf16" rounds both operands of each weight product to bfloat16 (8 bits of
mantissa) and accumulates the sum in float32 (`preferred_element_type`), the products' result staying
float32; parameters, optimiser state, activations, nonlinearities, BatchNorm, losses and metrics stay
float32. On a CPU with bfloat16 instructions (`avx512_bf16`, `amx_bf16`) XLA's bfloat16 products run
at up to about twice the float32 rate (this machine's measured peaks: benchmarks/README.md); on a CPU
without them they are emulated and slower. Layers whose numbers are sensitive to rounding keep
float32 whatever the option: GSPS's flow prior (its log-determinant and exact inverse), the metrics
and the action classifier behind CMD / FID.

Layers take the choice as a module attribute (`precision`), a static part of the module, so a jitted
function traced with one choice is never reused for the other.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

PRECISIONS = ("float32", "bf16")


def check(precision: str, what: str = "precision") -> str:
    """Returns `precision` when it is one of `PRECISIONS`, else raises ValueError naming `what`."""
    if precision not in PRECISIONS:
        raise ValueError(f"{what} must be one of {PRECISIONS}, got {precision!r}")
    return precision


def matmul(x: Float[ArrayLike, "... i"], w: Float[ArrayLike, "i o"], precision: str = "float32") -> Float[Array, "... o"]:
    """Returns `x @ w` (`w` 2-D): in float32, or with bfloat16 operands and float32 accumulation."""
    if precision == "float32":
        return x @ w
    check(precision)
    x, w = jnp.asarray(x), jnp.asarray(w)
    dims = (((x.ndim - 1,), (0,)), ((), ()))
    return jax.lax.dot_general(x.astype(jnp.bfloat16), w.astype(jnp.bfloat16), dims, preferred_element_type=jnp.float32)


def einsum(spec: str, a: ArrayLike, b: ArrayLike, precision: str = "float32") -> Array:
    """Returns `jnp.einsum(spec, a, b)`: in float32, or with bfloat16 operands and float32 accumulation."""
    if precision == "float32":
        return jnp.einsum(spec, a, b)
    check(precision)
    bf = jnp.bfloat16
    return jnp.einsum(spec, jnp.asarray(a).astype(bf), jnp.asarray(b).astype(bf), preferred_element_type=jnp.float32)
