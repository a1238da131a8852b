"""`Config.precision`: bfloat16 weight products with float32 accumulation (jaxmotion/nn/precision.py)."""

from __future__ import annotations

import dataclasses
import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.config import Config, validate
from jaxmotion.errors import ConfigError
from jaxmotion.models import dlow, divsamp, gsps
from jaxmotion.nn import precision as P
from jaxmotion.nn.execution import Execution


def test_an_unknown_precision_is_refused_by_the_config_the_execution_and_the_product():
    with pytest.raises(ConfigError, match="precision must be one of"):
        validate(dataclasses.replace(Config(), precision="fp16"))
    with pytest.raises(ValueError, match="precision must be one of"):
        P.matmul(jnp.ones((2, 3)), jnp.ones((3, 4)), "fp16")
    with pytest.raises(ValueError, match="Execution.precision must be one of"):
        Execution(precision="fp16")


def test_bf16_product_rounds_the_operands_and_accumulates_in_float32():
    x = jax.random.normal(jax.random.key(0), (5, 7, 300))
    w = jax.random.normal(jax.random.key(1), (300, 64))
    f32, bf = P.matmul(x, w), P.matmul(x, w, "bf16")
    assert f32.dtype == bf.dtype == jnp.float32
    np.testing.assert_array_equal(f32, x @ w)  # float32 is the plain product
    # The exact product of the bfloat16-rounded operands, summed in float64: float32 accumulation
    # leaves only float32 rounding on top (a bfloat16 accumulator would be off by ~1e-2 relative).
    xr, wr = (np.asarray(a.astype(jnp.bfloat16).astype(jnp.float32), np.float64) for a in (x, w))
    np.testing.assert_allclose(bf, xr @ wr, rtol=1e-4, atol=1e-4)
    assert 1e-4 < float(jnp.abs(bf - f32).max() / jnp.abs(f32).max()) < 2e-2  # it did round
    e32, ebf = P.graph_matmul(w[:7, :7], x[..., :4]), P.graph_matmul(w[:7, :7], x[..., :4], "bf16")
    np.testing.assert_array_equal(e32, jnp.einsum("ij,...jo->...io", w[:7, :7], x[..., :4]))
    np.testing.assert_allclose(ebf, e32, rtol=0, atol=0.05 * float(jnp.abs(e32).max()))


@pytest.mark.parametrize("precision", P.PRECISIONS)
def test_weight_products_of_many_axes_are_2d_products_with_the_same_gradients(precision):
    # A 3-D x is multiplied as its 2-D view, so both gradient products are 2-D (benchmarks/results/optimisations.md,
    # "Weight products on 2-D views"): from the 3-D form XLA:CPU copies the cotangent into a transposed layout.
    x = jax.random.normal(jax.random.key(0), (4, 6, 9))
    w = jax.random.normal(jax.random.key(1), (9, 5))
    ct = jax.random.normal(jax.random.key(2), (4, 6, 5))
    out, vjp = jax.vjp(lambda x, w: P.matmul(x, w, precision), x, w)
    r = (lambda v: v.astype(jnp.bfloat16).astype(jnp.float32)) if precision == "bf16" else (lambda v: v)  # noqa: E731
    ref, vjp_ref = jax.vjp(lambda x, w: jnp.einsum("abi,io->abo", x, w), r(x), r(w))
    assert out.shape == (4, 6, 5)
    np.testing.assert_allclose(out, ref, rtol=1e-5, atol=1e-5)
    for got, want in zip(vjp(ct), vjp_ref(r(ct))):
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    grad = jax.grad(lambda x, w: jnp.sum(P.matmul(x, w, precision) ** 2), argnums=(0, 1))
    dots = [line for line in jax.jit(grad).lower(x, w).as_text().splitlines() if "dot_general" in line]
    assert len(dots) == 3  # forward, dx, dw
    for line in dots:  # every operand and result 2-D
        assert all(t.count("x") == 2 for t in re.findall(r"tensor<([^>]*)>", line)), line


@pytest.mark.parametrize("two_axis_min", [P.NODE_GRAD_TWO_AXIS_MIN, 0])  # both forms of dA
def test_node_major_adjacency_product_and_its_gradients_are_the_einsums(monkeypatch, two_axis_min):
    monkeypatch.setattr(P, "NODE_GRAD_TWO_AXIS_MIN", two_axis_min)
    a = jax.random.normal(jax.random.key(0), (6, 6))
    h = jax.random.normal(jax.random.key(1), (6, 4, 3, 5))
    ct = jax.random.normal(jax.random.key(2), (6, 4, 3, 5))
    plain = lambda a, h: jnp.einsum("ij,j...->i...", a, h)  # noqa: E731
    out, vjp = jax.vjp(P.node_matmul, a, h)
    ref, vjp_ref = jax.vjp(plain, a, h)
    np.testing.assert_allclose(out, ref, rtol=1e-6, atol=1e-6)
    for got, want in zip(vjp(ct), vjp_ref(ct)):
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert P.node_matmul(a, h[:, 0, 0]).shape == (6, 5)  # no middle axes
    with jax.enable_x64(True):  # float32 keeps the operands' dtype: float64 stays float64
        a64 = jnp.asarray(np.asarray(a), jnp.float64)
        assert P.node_matmul(a64, jnp.asarray(np.asarray(h), jnp.float64)).dtype == jnp.float64


@pytest.mark.parametrize("shape", [(4, 1024, 256), (4, 8, 32)])  # M x F = 2^18 (two-axis form), 2^8 (2-D form)
def test_node_major_adjacency_gradient_takes_the_form_its_size_calls_for(shape):
    # Lowered only, not run: which contraction dA is written as (benchmarks/results/optimisations.md, "The adjacency gradient").
    a = jax.ShapeDtypeStruct((4, 4), jnp.float32)
    h = jax.ShapeDtypeStruct(shape, jnp.float32)
    grad = jax.grad(lambda a, h: jnp.sum(P.node_matmul(a, h) ** 2), argnums=(0, 1))
    dots = [line for line in jax.jit(grad).lower(a, h).as_text().splitlines() if "dot_general" in line]
    da = [line for line in dots if line.rstrip().endswith("tensor<4x4xf32>")]
    assert len(da) == 1
    big = math.prod(h.shape[1:]) >= P.NODE_GRAD_TWO_AXIS_MIN
    assert ("contracting_dims = [1, 2] x [1, 2]" in da[0]) == big
    assert ("contracting_dims = [1] x [1]" in da[0]) == (not big)


@pytest.mark.parametrize("fn", ["matmul", "graph_matmul", "node_matmul"])
def test_bf16_gradients_are_bf16_products_of_the_rounded_operands(fn):
    a = jax.random.normal(jax.random.key(0), (4, 6, 6) if fn == "matmul" else (6, 6))
    b = jax.random.normal(jax.random.key(1), {"matmul": (6, 5), "graph_matmul": (4, 6, 5), "node_matmul": (6, 4, 5)}[fn])
    ct = jax.random.normal(jax.random.key(2), (6, 4, 5) if fn == "node_matmul" else (4, 6, 5))
    f = getattr(P, fn)
    out, vjp = jax.vjp(lambda a, b: f(a, b, "bf16"), a, b)
    da, db = vjp(ct)
    # The reference: float32 gradients of the float32 product at the bfloat16-rounded operands and cotangent.
    r = lambda v: v.astype(jnp.bfloat16).astype(jnp.float32)  # noqa: E731
    _, vjp32 = jax.vjp(lambda a, b: f(a, b), r(a), r(b))
    ra, rb = vjp32(r(ct))
    assert da.dtype == db.dtype == jnp.float32
    np.testing.assert_allclose(da, ra, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(db, rb, rtol=1e-5, atol=1e-5)
    hlo = jax.jit(jax.grad(lambda a, b: jnp.sum(f(a, b, "bf16") ** 2), argnums=(0, 1))).lower(a, b).as_text()
    dots = [line.split(":")[-1].split("->")[0] for line in hlo.splitlines() if "dot_general" in line]
    assert len(dots) >= 3 and all("xf32" not in operands for operands in dots)  # forward and backward: bf16 operands


def _bf16_dots(fn, *args) -> int:
    return jax.jit(fn).lower(*args).as_text().count("bf16")


def test_dlow_models_compute_in_bf16_with_the_same_parameters():
    x = jax.random.normal(jax.random.key(0), (4, 8, 12))
    y = jax.random.normal(jax.random.key(1), (4, 10, 12))
    c = dlow.CVAEConfig(nz=8, nh_rnn=16, nh_mlp=(32, 16))
    m32, mbf = dlow.cvae_model(c, 12, 10), dlow.cvae_model(c, 12, 10, Execution(precision="bf16"))
    p = jax.jit(m32.init)(jax.random.key(2), x, y)
    assert jax.tree.structure(p) == jax.tree.structure(jax.eval_shape(mbf.init, jax.random.key(2), x, y))
    z = jax.random.normal(jax.random.key(3), (4, 5, 8))
    out32, outbf = (jax.jit(lambda z, m=m: dlow.decode_k(m, p, x, z))(z) for m in (m32, mbf))
    assert outbf.dtype == jnp.float32
    np.testing.assert_allclose(outbf, out32, atol=0.05 * float(jnp.abs(out32).max()))
    assert not np.array_equal(outbf, out32)
    assert _bf16_dots(lambda z: dlow.decode_k(mbf, p, x, z), z) > 0
    assert _bf16_dots(lambda z: dlow.decode_k(m32, p, x, z), z) == 0
    q = dlow.q_model(dlow.QConfig(nh_rnn=16, nh_mlp=(32,)), 8, 5, Execution(precision="bf16"))
    qp = jax.jit(q.init)(jax.random.key(4), x, jnp.zeros((4, 8)))
    g = jax.jit(jax.grad(lambda qp: jnp.sum(q.apply(qp, x, jnp.ones((4, 8)))[0] ** 2)))(qp)
    assert all(bool(jnp.all(jnp.isfinite(v))) and v.dtype == jnp.float32 for v in jax.tree.leaves(g))


def test_divsamp_and_gsps_graph_convolutions_compute_in_bf16():
    d = divsamp.DivSampConfig(n_dct=4, hidden=16, nz=8, cvae_residual=1, sampler_residual=1, num_bases=5, base_dim=8, nh=8)
    cx = jax.random.normal(jax.random.key(0), (3, 6, 12))
    m32, mbf = divsamp.cvae_from_config(d), divsamp.cvae_from_config(d, Execution(precision="bf16"))
    v = jax.jit(lambda k: m32.init(k, cx, cx, jax.random.key(2), train=False))(jax.random.key(1))
    a, b = (jax.jit(lambda cx, m=m: m.apply(v, cx, cx, train=False)[0])(cx) for m in (m32, mbf))
    np.testing.assert_allclose(b, a, atol=0.05 * float(jnp.abs(a).max()))
    assert _bf16_dots(lambda cx: mbf.apply(v, cx, cx, train=False)[0], cx) > 0
    s = divsamp.sampler_from_config(d, Execution(precision="bf16"))
    sv = jax.jit(lambda k: s.init(k, cx, jax.random.key(4), 5, train=False))(jax.random.key(3))
    assert bool(jnp.all(jnp.isfinite(jax.jit(lambda cx: s.apply(sv, cx, jax.random.key(5), 5, train=False)[0])(cx))))
    gen = gsps.GSPSGenerator(parts=((0, 1, 2), (3, 4, 5)), hidden=16, num_stage=1, execution=Execution(precision="bf16"))
    z = jax.random.normal(jax.random.key(6), (3, 2, 4))
    g32 = gsps.GSPSGenerator(parts=((0, 1, 2), (3, 4, 5)), hidden=16, num_stage=1)
    gv = jax.jit(lambda k: g32.init(k, cx, z, train=False))(jax.random.key(7))
    assert _bf16_dots(lambda cx: gen.apply(gv, cx, z, train=False), cx) > 0
