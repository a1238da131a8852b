"""Graph convolutions over joints with a learnable adjacency, and GCL-BN-Tanh stacks.

Inputs are node features `(..., J, F)`: J graph nodes (joints) with F features each (for
DivSamp and GSPS, the first `n_dct` DCT coefficients of each coordinate, `F = 3 * n_dct`).
A layer computes `H' = A H W + b` (Mao et al., ICCV 2019 "Learning Trajectory Dependencies",
Eq. (1)) with a dense, learnable `A` (J x J) that starts random rather than from the kinematic
tree, as in the DivSamp and GSPS releases (`GraphConv`: weight, att and bias all drawn from
U(-1/sqrt(F_out), 1/sqrt(F_out))).

A GCL-BN-Tanh block normalises each of the J * F outputs separately (PyTorch `BatchNorm1d(J * F)`
on the flattened features, as in the releases), so the BatchNorm statistics live in the
`batch_stats` collection: apply with `train=True, mutable=["batch_stats"]` while training and
`train=False` (running averages) to evaluate. The running variance is kept as PyTorch keeps it
(unbiased; nn/batchnorm.py). Every block takes BatchNorm's `repeats` (each input row stands for that
many equal rows of the batch; nn/batchnorm.py) as a call argument.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.batchnorm import BatchNorm
from jaxmotion.nn.precision import graph_matmul, matmul, node_matmul


def _uniform(bound: float):
    return lambda key, shape, dtype=jnp.float32: jax.random.uniform(key, shape, dtype, -bound, bound)


class GraphConv(nn.Module):
    """Returns `A H W + b` for node features H `(..., J, F_in)`: a graph convolution with learnable A (J x J).

    With `node_major=True` the input and output are laid out `(J, ..., F)`: the adjacency product
    is then one `(J, J) @ (J, rest)` matrix product with no transposes (see `GCLStack`), its
    gradient in the product shape XLA:CPU runs fastest (`precision.node_matmul`).
    """

    features: int
    use_bias: bool = True
    precision: str = "float32"  # the products': "float32" or "bf16" (nn/precision.py)
    node_major: bool = False

    @nn.compact
    def __call__(self, h: Float[ArrayLike, "... j f"]) -> Float[Array, "... j o"]:
        j, f_in = (h.shape[0], h.shape[-1]) if self.node_major else h.shape[-2:]
        init = _uniform(1.0 / float(self.features) ** 0.5)
        w = self.param("kernel", init, (f_in, self.features))
        a = self.param("adjacency", init, (j, j))
        g = matmul(h, w, self.precision)
        if self.node_major:
            out = node_matmul(a, g, self.precision)
        else:
            out = graph_matmul(a, g, self.precision)
        if self.use_bias:
            out = out + self.param("bias", init, (self.features,))
        return out


class GCLBlock(nn.Module):
    """Returns `tanh(BN(GraphConv(H)))` `(..., J, F_out)`: one GCL-BN-Tanh layer.

    BatchNorm statistics are taken over every leading axis (batch, and K when present) for each
    of the J * F_out features; PyTorch's defaults (momentum 0.1, eps 1e-5) are kept.
    """

    features: int
    precision: str = "float32"  # as GraphConv.precision
    node_major: bool = False  # as GraphConv.node_major
    per_device_bn: bool = False  # BatchNorm.per_device: each device's own training moments

    @nn.compact
    def __call__(self, h: Float[ArrayLike, "... j f"], *, train: bool, repeats: int = 1) -> Float[Array, "... j o"]:
        x = GraphConv(self.features, precision=self.precision, node_major=self.node_major, name="gc")(h)
        bn = BatchNorm(
            use_running_average=not train, momentum=0.9, epsilon=1e-5, node_major=self.node_major,
            per_device=self.per_device_bn, name="bn",
        )
        if self.node_major:
            return jnp.tanh(bn(x, repeats))
        shape = x.shape
        return jnp.tanh(bn(x.reshape(shape[:-2] + (shape[-2] * shape[-1],)), repeats).reshape(shape))


class ResidualGCLBlock(nn.Module):
    """Returns `H + GCL(GCL(H))`: two GCL-BN-Tanh layers with a skip connection (`ResGCB` in the releases)."""

    features: int
    precision: str = "float32"  # as GraphConv.precision
    node_major: bool = False  # as GraphConv.node_major
    per_device_bn: bool = False  # as GCLBlock.per_device_bn

    @nn.compact
    def __call__(self, h: Float[ArrayLike, "... j f"], *, train: bool, repeats: int = 1) -> Float[Array, "... j f"]:
        x = GCLBlock(h.shape[-1], self.precision, self.node_major, self.per_device_bn, name="gcl_0")(h, train=train, repeats=repeats)
        x = GCLBlock(self.features, self.precision, self.node_major, self.per_device_bn, name="gcl_1")(x, train=train, repeats=repeats)
        return x + h


class GCLStack(nn.Module):
    """Returns node features `(..., J, features)` after `1 + 2 * num_residual` GCL-BN-Tanh layers.

    One GCL-BN-Tanh layer maps the input to `features`, then `num_residual` residual pairs follow:
    DivSamp's CVAE encoder and decoder use 4 pairs (9 layers, supp. Table 4), its sampler N_beta 2
    (5 layers, supp. Table 3).

    Input and output are `(..., J, F)`. Inside, the stack runs node-major (`node_major=True`, the
    default): one transpose to `(J, ..., F)` on the way in and one on the way out, so every
    adjacency product is a plain `(J, J) @ (J, rest)` product. The batch-major layout computes
    `einsum("ij,...jo->...io")`, which XLA's CPU backend runs with a transpose of its operand and
    result around every layer (measured in benchmarks/results/optimisations.md, "Node-major graph convolutions").
    Both layouts have the same parameters and statistics, so checkpoints load in either.
    """

    features: int
    num_residual: int
    precision: str = "float32"  # as GraphConv.precision
    node_major: bool = True
    per_device_bn: bool = False  # as GCLBlock.per_device_bn

    @nn.compact
    def __call__(self, h: Float[ArrayLike, "... j f"], *, train: bool, repeats: int = 1) -> Float[Array, "... j o"]:
        nm = self.node_major
        if nm:
            h = jnp.moveaxis(jnp.asarray(h), -2, 0)
        bn = self.per_device_bn
        h = GCLBlock(self.features, self.precision, nm, bn, name="gcl_in")(h, train=train, repeats=repeats)
        for i in range(self.num_residual):
            h = ResidualGCLBlock(self.features, self.precision, nm, bn, name=f"res_{i}")(h, train=train, repeats=repeats)
        return jnp.moveaxis(h, 0, -2) if nm else h
