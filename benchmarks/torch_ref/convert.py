"""Loads jaxmotion (Flax) parameters into the PyTorch reference modules.

Flax `Dense` kernels are `(in, out)` and jaxmotion's GRU weights `(in, 3h)`; PyTorch stores
`(out, in)` and `(3h, in)`, so every conversion is a transpose, with identical gate order (r, z, n);
Flax 1 x 1 convolution kernels `(1, 1, in, out)` become `nn.Conv2d`'s `(out, in, 1, 1)`.
Parameters are taken from any nested mapping of array-likes (a Flax params pytree, or numpy arrays
read back from an `.npz`), so this module needs no JAX.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch
from torch import nn

from benchmarks.torch_ref import diffusion, divsamp, dlow, gsps, mojo, motionmap
from benchmarks.torch_ref.layers import GRU, MLP


def _t(a) -> torch.Tensor:
    return torch.from_numpy(np.array(a, dtype=np.float32, copy=True))


def _inner(p: Mapping) -> Mapping:
    return p["params"] if "params" in p else p


def _copy(dst: torch.Tensor, src: torch.Tensor, name: str) -> None:
    if tuple(dst.shape) != tuple(src.shape):
        raise ValueError(f"{name}: jaxmotion shape {tuple(src.shape)} does not fit PyTorch shape {tuple(dst.shape)}")
    with torch.no_grad():
        dst.copy_(src)


def load_dense(layer: nn.Linear, p: Mapping, name: str = "dense") -> None:
    """Copies a Flax `Dense` (`kernel (in, out)`, `bias`) into `nn.Linear`."""
    _copy(layer.weight, _t(p["kernel"]).T, f"{name}.kernel")
    _copy(layer.bias, _t(p["bias"]), f"{name}.bias")


def load_mlp(mlp: MLP, p: Mapping, name: str = "mlp") -> None:
    """Copies jaxmotion's MLP (`dense_0`, `dense_1`, ...) into the reference MLP."""
    if len(p) != len(mlp.layers):
        raise ValueError(f"{name}: {len(p)} jaxmotion layers, {len(mlp.layers)} PyTorch layers")
    for i, layer in enumerate(mlp.layers):
        load_dense(layer, p[f"dense_{i}"], f"{name}.dense_{i}")


def load_gru_cell(cell: nn.GRUCell, p: Mapping, name: str = "cell") -> None:
    """Copies jaxmotion's GRUCell (`weight_ih (in, 3h)`, ...) into `nn.GRUCell`."""
    _copy(cell.weight_ih, _t(p["weight_ih"]).T, f"{name}.weight_ih")
    _copy(cell.weight_hh, _t(p["weight_hh"]).T, f"{name}.weight_hh")
    _copy(cell.bias_ih, _t(p["bias_ih"]), f"{name}.bias_ih")
    _copy(cell.bias_hh, _t(p["bias_hh"]), f"{name}.bias_hh")


def load_gru(gru: GRU, p: Mapping, name: str = "gru") -> None:
    """Copies jaxmotion's scanned GRU (`cell/...`) into the one-layer `nn.GRU`."""
    c = p["cell"]
    _copy(gru.rnn.weight_ih_l0, _t(c["weight_ih"]).T, f"{name}.weight_ih")
    _copy(gru.rnn.weight_hh_l0, _t(c["weight_hh"]).T, f"{name}.weight_hh")
    _copy(gru.rnn.bias_ih_l0, _t(c["bias_ih"]), f"{name}.bias_ih")
    _copy(gru.rnn.bias_hh_l0, _t(c["bias_hh"]), f"{name}.bias_hh")


def dlow_cvae(model: dlow.DLowCVAE, params: Mapping) -> dlow.DLowCVAE:
    """Returns `model` holding the jaxmotion DLowCVAE `params`."""
    p = _inner(params)
    load_gru(model.x_rnn, p["x_rnn"], "x_rnn")
    load_gru(model.e_rnn, p["e_rnn"], "e_rnn")
    load_mlp(model.e_mlp, p["e_mlp"], "e_mlp")
    load_dense(model.e_mu, p["e_mu"], "e_mu")
    load_dense(model.e_logvar, p["e_logvar"], "e_logvar")
    load_mlp(model.drnn_mlp, p["drnn_mlp"], "drnn_mlp")
    load_gru_cell(model.d_cell, p["d_cell"], "d_cell")
    load_mlp(model.d_mlp, p["d_mlp"], "d_mlp")
    load_dense(model.d_out, p["d_out"], "d_out")
    return model


def dlow_q(model: dlow.DLowQ, params: Mapping) -> dlow.DLowQ:
    """Returns `model` holding the jaxmotion DLowQ `params`."""
    p = _inner(params)
    load_gru(model.x_rnn, p["x_rnn"], "x_rnn")
    load_mlp(model.mlp, p["mlp"], "mlp")
    load_dense(model.head_A, p["head_A"], "head_A")
    load_dense(model.head_b, p["head_b"], "head_b")
    return model


def mojo_cvae(model: mojo.MojoCVAE, params: Mapping) -> mojo.MojoCVAE:
    """Returns `model` holding the jaxmotion MojoCVAE `params` (the same layer names as DLow's CVAE)."""
    return dlow_cvae(model, params)


def mojo_q(model: mojo.MojoQ, params: Mapping) -> mojo.MojoQ:
    """Returns `model` holding the jaxmotion MojoQ `params` (shared trunk: `q/x_rnn`, `q/mlp`, `q/head_*`)."""
    return dlow_q(model, _inner(params)["q"])


def load_batchnorm(bn: nn.BatchNorm1d, p: Mapping, stats: Mapping | None, name: str = "bn") -> None:
    """Copies a Flax `BatchNorm` (`scale`, `bias`; running `mean`, `var`) into `nn.BatchNorm1d`."""
    _copy(bn.weight, _t(p["scale"]), f"{name}.scale")
    _copy(bn.bias, _t(p["bias"]), f"{name}.bias")
    if stats is not None:
        _copy(bn.running_mean, _t(stats["mean"]), f"{name}.mean")
        _copy(bn.running_var, _t(stats["var"]), f"{name}.var")


def load_graph_conv(gc: divsamp.GraphConv, p: Mapping, name: str = "gc") -> None:
    _copy(gc.weight, _t(p["kernel"]), f"{name}.kernel")
    _copy(gc.att, _t(p["adjacency"]), f"{name}.adjacency")
    _copy(gc.bias, _t(p["bias"]), f"{name}.bias")


def _sub(stats: Mapping | None, key: str):
    return None if stats is None else stats[key]


def load_gcl(block: divsamp.GCLBlock, p: Mapping, stats: Mapping | None, name: str) -> None:
    load_graph_conv(block.gc, p["gc"], f"{name}.gc")
    load_batchnorm(block.bn, p["bn"], _sub(stats, "bn"), f"{name}.bn")


def load_gcl_stack(stack: divsamp.GCLStack, p: Mapping, stats: Mapping | None, name: str) -> None:
    load_gcl(stack.gcl_in, p["gcl_in"], _sub(stats, "gcl_in"), f"{name}.gcl_in")
    if len(stack.res) != sum(k.startswith("res_") for k in p):
        raise ValueError(f"{name}: {sum(k.startswith('res_') for k in p)} jaxmotion residual blocks, {len(stack.res)} PyTorch")
    for i, block in enumerate(stack.res):
        r, rs = p[f"res_{i}"], _sub(stats, f"res_{i}")
        load_gcl(block.gcl_0, r["gcl_0"], _sub(rs, "gcl_0"), f"{name}.res_{i}.gcl_0")
        load_gcl(block.gcl_1, r["gcl_1"], _sub(rs, "gcl_1"), f"{name}.res_{i}.gcl_1")


def divsamp_cvae(model: divsamp.DivSampCVAE, variables: Mapping) -> divsamp.DivSampCVAE:
    """Returns `model` holding the jaxmotion DivSampCVAE `variables` (`params` and `batch_stats`)."""
    p, s = variables["params"], variables.get("batch_stats")
    load_gcl_stack(model.enc, p["enc"], _sub(s, "enc"), "enc")
    load_dense(model.e_mu, p["e_mu"], "e_mu")
    load_dense(model.e_logvar, p["e_logvar"], "e_logvar")
    load_gcl_stack(model.dec, p["dec"], _sub(s, "dec"), "dec")
    load_graph_conv(model.d_out, p["d_out"], "d_out")
    return model


def divsamp_sampler(model: divsamp.DivSampSampler, variables: Mapping) -> divsamp.DivSampSampler:
    """Returns `model` holding the jaxmotion DivSampSampler `variables` (uniform pi: no `pi_*` parameters)."""
    p, s = variables["params"], variables.get("batch_stats")
    if "pi_logits" in p or "pi_head" in p:
        raise ValueError("divsamp_sampler: the reference sampler has a uniform pi; got a learned pi")
    load_gcl_stack(model.condition_enc, p["condition_enc"], _sub(s, "condition_enc"), "condition_enc")
    load_dense(model.bases, p["bases"], "bases")
    load_batchnorm(model.bases_bn, p["bases_bn"], _sub(s, "bases_bn"), "bases_bn")
    for head in ("mean", "logvar"):
        m, hp = getattr(model, head), p[head]
        load_dense(m.dense_0, hp["dense_0"], f"{head}.dense_0")
        load_batchnorm(m.bn, hp["bn"], _sub(_sub(s, head), "bn"), f"{head}.bn")
        load_dense(m.dense_1, hp["dense_1"], f"{head}.dense_1")
    return model


def gsps_prior(model: gsps.PosePrior, params: Mapping) -> gsps.PosePrior:
    """Returns `model` holding the jaxmotion PosePrior `params` (`linqr_i`: householder, r, bias; `prelu_i`: log_slope)."""
    p = _inner(params)
    n_lin = sum(isinstance(m, gsps.LinQR) for m in model.layers)
    if n_lin != sum(k.startswith("linqr_") for k in p):
        raise ValueError(f"gsps_prior: {sum(k.startswith('linqr_') for k in p)} jaxmotion LinQR layers, {n_lin} PyTorch")
    i_lin = i_prelu = 0
    for layer in model.layers:
        if isinstance(layer, gsps.LinQR):
            q = p[f"linqr_{i_lin}"]
            for name in ("householder", "r", "bias"):
                _copy(getattr(layer, name), _t(q[name]), f"linqr_{i_lin}.{name}")
            i_lin += 1
        else:
            _copy(layer.log_slope, _t(p[f"prelu_{i_prelu}"]["log_slope"]), f"prelu_{i_prelu}.log_slope")
            i_prelu += 1
    return model


def gsps_generator(model: gsps.GSPSGenerator, variables: Mapping) -> gsps.GSPSGenerator:
    """Returns `model` holding the jaxmotion GSPSGenerator `variables` (`params`, and `batch_stats` when present)."""
    p, s = variables["params"], variables.get("batch_stats")
    if len(model.parts) != len(p):
        raise ValueError(f"gsps_generator: {len(p)} jaxmotion part GCNs, {len(model.parts)} PyTorch")
    for i, part in enumerate(model.parts):
        name = f"part_{i}"
        load_gcl_stack(part.gcn, p[name]["gcn"], _sub(_sub(s, name), "gcn"), f"{name}.gcn")
        load_graph_conv(part.out, p[name]["out"], f"{name}.out")
    return model


def load_conv1x1(conv: nn.Conv2d, p: Mapping, name: str = "conv") -> None:
    """Copies a Flax 1 x 1 `Conv` (`kernel (1, 1, in, out)`, `bias`) into `nn.Conv2d`."""
    _copy(conv.weight, _t(p["kernel"]).permute(3, 2, 0, 1), f"{name}.kernel")
    _copy(conv.bias, _t(p["bias"]), f"{name}.bias")


def motionmap_ae(model: motionmap.MotionMapAE, params: Mapping) -> motionmap.MotionMapAE:
    """Returns `model` holding the jaxmotion MotionMapAE `params`."""
    p = _inner(params)
    load_gru(model.enc_x, p["enc_x"], "enc_x")
    load_gru(model.enc_y, p["enc_y"], "enc_y")
    load_mlp(model.fusion, p["fusion"], "fusion")
    d = p["decoder"]
    load_dense(model.decoder.h0, d["h0"], "decoder.h0")
    load_gru_cell(model.decoder.cell, d["cell"], "decoder.cell")
    load_dense(model.decoder.out, d["out"], "decoder.out")
    load_mlp(model.uncertainty, p["uncertainty"], "uncertainty")
    load_dense(model.uncertainty_out, p["uncertainty_out"], "uncertainty_out")
    return model


def motionmap_heatmap(model: motionmap.HeatmapNet, params: Mapping) -> motionmap.HeatmapNet:
    """Returns `model` holding the jaxmotion HeatmapNet `params` (GRU, LayerNorm, map layer, 1 x 1 convolutions)."""
    p = _inner(params)
    load_gru(model.context, p["context"], "context")
    _copy(model.norm.weight, _t(p["norm"]["scale"]), "norm.scale")
    _copy(model.norm.bias, _t(p["norm"]["bias"]), "norm.bias")
    load_dense(model.to_map, p["to_map"], "to_map")
    n = sum(k.startswith("conv_") for k in p)
    if n != len(model.convs):
        raise ValueError(f"motionmap_heatmap: {n} jaxmotion convolutions, {len(model.convs)} PyTorch")
    for i, conv in enumerate(model.convs):
        load_conv1x1(conv, p[f"conv_{i}"], f"conv_{i}")
    load_conv1x1(model.final, p["final"], "final")
    return model


def load_layer_norm(norm: nn.LayerNorm, p: Mapping, name: str = "norm") -> None:
    """Copies a Flax `LayerNorm` (`scale`, `bias`) into `nn.LayerNorm`."""
    _copy(norm.weight, _t(p["scale"]), f"{name}.scale")
    _copy(norm.bias, _t(p["bias"]), f"{name}.bias")


def _load_stylization(st: diffusion.Stylization, p: Mapping, name: str) -> None:
    load_dense(st.emb, p["emb"], f"{name}.emb")
    load_layer_norm(st.norm, p["norm"], f"{name}.norm")
    load_dense(st.out, p["out"], f"{name}.out")


def diffusion_denoiser(model: diffusion.Denoiser, params: Mapping) -> diffusion.Denoiser:
    """Returns `model` holding the jaxmotion diffusion `Denoiser` `params` (bias-free query/key/value included)."""
    p = _inner(params)
    for name in ("time_in", "time_out", "cond_embed", "joint_embed", "out"):
        load_dense(getattr(model, name), p[name], name)
    _copy(model.sequence_embedding, _t(p["sequence_embedding"]), "sequence_embedding")
    n = sum(k.startswith("block_") for k in p)
    if n != len(model.blocks):
        raise ValueError(f"diffusion_denoiser: {n} jaxmotion blocks, {len(model.blocks)} PyTorch")
    for i, block in enumerate(model.blocks):
        b, name = p[f"block_{i}"], f"block_{i}"
        load_layer_norm(block.attn_norm, b["attn_norm"], f"{name}.attn_norm")
        for w in ("query", "key", "value"):
            _copy(getattr(block, w).weight, _t(b[w]["kernel"]).T, f"{name}.{w}.kernel")
        _load_stylization(block.attn_style, b["attn_style"], f"{name}.attn_style")
        load_dense(block.ff_in, b["ff_in"], f"{name}.ff_in")
        load_dense(block.ff_out, b["ff_out"], f"{name}.ff_out")
        _load_stylization(block.ff_style, b["ff_style"], f"{name}.ff_style")
    return model


def flatten(params: Mapping, prefix: str = "") -> dict[str, np.ndarray]:
    """Returns `{"a/b/c": array}` for a nested mapping (for saving to `.npz`)."""
    out = {}
    for k, v in params.items():
        if isinstance(v, Mapping):
            out.update(flatten(v, f"{prefix}{k}/"))
        else:
            out[f"{prefix}{k}"] = np.asarray(v)
    return out


def unflatten(flat: Mapping[str, np.ndarray]) -> dict:
    """Returns the nested dict that `flatten` flattened."""
    out: dict = {}
    for key, v in flat.items():
        *path, leaf = key.split("/")
        d = out
        for part in path:
            d = d.setdefault(part, {})
        d[leaf] = v
    return out
