"""A DCT-space diffusion predictor of the HumanMAC class (Chen et al., ICCV 2023).

The window of `t_his + t_pred` frames lives in DCT space: its first `n_dct` coefficients along time
(`jaxmotion.dct`) are the diffusion variable `x0 (n_dct, D)`. Training is DDPM's noise prediction
(Ho et al. 2020, Eq. (14)): `x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps` with the cosine schedule of
Nichol & Dhariwal (2021, Eq. (17)), and the loss `||eps - eps_theta(x_t, t, c)||^2`. The condition `c`
is the DCT of the observed frames padded with the last observed pose (HumanMAC Sec. 3.2), dropped for
a fraction of training samples. The denoiser is a transformer over the `n_dct` coefficients whose
every block is modulated by the timestep (+ condition) embedding (stylization / FiLM: LayerNorm, then
`* (1 + scale) + shift`), with long skips from the first half of the blocks to the second.

Sampling is DDIM (Song et al. 2021, Eq. (12) with sigma = 0) on a sub-sequence of the training
timesteps, with HumanMAC's DCT completion (Sec. 3.3, Eq. (6)-(7)) after each step: the padded
observation is noised to the step's level, both it and the sample go back to time, the masked
(observed) frames are taken from the observation, and the result returns to DCT space. The whole
loop is one `lax.scan`: `sample_reference` vmaps `ddim_sample` of the Flax denoiser over the K samples
(the readable definition); `sample` computes the same futures with the K samples in the batch of every
product and the step-invariant terms computed once (tested equal).

Sizes follow the release's `cfg/h36m.yml` (8 blocks, 8 heads, width 512, 20 coefficients, 1000
noise steps, 100 DDIM steps, condition kept for 80% of training samples, EMA 0.995 after 2000 steps).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Float, Int

from jaxmotion.dct import dct, dct_matrix, idct
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.linear import Dense, initializers
from jaxmotion.nn.precision import matmul

__all__ = ["DiffusionConfig", "Denoiser", "denoiser", "cosine_betas", "linear_betas", "Schedule", "schedule",
           "ddim_timesteps", "pad_last", "condition", "q_sample", "diffusion_loss", "completion_mask", "ddim_sample",
           "sample", "sample_reference", "ema_weights"]

SCHEDULES = ("cosine", "linear")


@dataclasses.dataclass
class DiffusionConfig:
    """The diffusion predictor's settings (`Config.method_config` of method "diffusion").

    The defaults are sized for Bandai-Namco-2 on a CPU; `experiments/configs/diffusion_h36m.py` has
    the release's Human3.6M sizes.
    """

    n_dct: int = 15  # DCT coefficients of the whole window kept (the release: 20 of 125 frames)
    latent: int = 64  # transformer width (the release: 512)
    ff: int = 128  # feed-forward width (the release: 1024)
    num_layers: int = 4  # blocks, an even number: the first half's inputs skip to the second half (the release: 8)
    num_heads: int = 4  # (the release: 8)
    dropout: float = 0.2
    noise_steps: int = 1000  # training timesteps T of the forward process
    schedule: str = "cosine"  # "cosine" (the release's) or "linear"
    sampling_steps: int = 25  # DDIM steps at test time, dividing noise_steps: 10 / 25 / 50 / 100 (the release: 100)
    cond_drop: float = 0.2  # fraction of training samples whose condition is dropped (the release keeps 0.8)
    # DCT completion's mask: the first `complete_frames` frames of the window (all coordinates) are taken
    # from the noised observation after every step; None: the t_his observed frames; 0: no completion.
    complete_frames: int | None = None
    ema_decay: float = 0.995
    ema_start: int = 500  # steps before the EMA starts averaging (it copies the weights until then; the release: 2000)
    lr: float = 3e-4
    batch_size: int = 64
    num_steps: int = 6000
    lr_fix_fraction: float = 0.5  # constant lr for this fraction of training, then linear decay to 0
    # The release's step decay instead (`MultiStepLR`): the lr is multiplied by `lr_gamma` at each of these
    # fractions of training (its epochs 75, 150, 225, 275, 350, 450 of 500: `lr_fix_fraction` is then unused).
    # Empty (default): the constant-then-linear schedule above.
    lr_milestones: tuple[float, ...] = ()
    lr_gamma: float = 0.9
    # The release's evaluation keeps the condition for a whole pass over the test windows with probability
    # `mod_test` and drops it otherwise (DCT completion alone then ties the sample to the observation), so
    # about that fraction of each window's K samples are conditioned. 1.0 (default): every sample is
    # conditioned. The release's HumanEva-I config: 0.5; Human3.6M: 1.0.
    test_cond_keep: float = 1.0

    def __post_init__(self):
        for name in ("n_dct", "latent", "ff", "num_layers", "num_heads", "noise_steps", "sampling_steps", "batch_size"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"DiffusionConfig.{name} must be an integer >= 1, got {v!r}")
        if self.num_layers % 2:
            raise ValueError(f"DiffusionConfig.num_layers must be even (long skips pair the halves), got {self.num_layers}")
        if self.latent % self.num_heads:
            raise ValueError(f"DiffusionConfig.latent ({self.latent}) must be a multiple of num_heads ({self.num_heads})")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"DiffusionConfig.schedule must be one of {SCHEDULES}, got {self.schedule!r}")
        if self.sampling_steps > self.noise_steps or self.noise_steps % self.sampling_steps:
            raise ValueError(
                f"DiffusionConfig.sampling_steps ({self.sampling_steps}) must divide noise_steps ({self.noise_steps})"
            )
        if not 0.0 <= self.cond_drop < 1.0:
            raise ValueError(f"DiffusionConfig.cond_drop must be in [0, 1), got {self.cond_drop}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"DiffusionConfig.dropout must be in [0, 1), got {self.dropout}")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"DiffusionConfig.ema_decay must be in [0, 1), got {self.ema_decay}")
        if self.complete_frames is not None and self.complete_frames < 0:
            raise ValueError(f"DiffusionConfig.complete_frames must be None or >= 0, got {self.complete_frames}")
        if not 0.0 <= self.test_cond_keep <= 1.0:
            raise ValueError(f"DiffusionConfig.test_cond_keep must be in [0, 1], got {self.test_cond_keep}")
        if any(not 0.0 < m < 1.0 for m in self.lr_milestones) or list(self.lr_milestones) != sorted(self.lr_milestones):
            raise ValueError(f"DiffusionConfig.lr_milestones must be increasing fractions in (0, 1), got {self.lr_milestones}")
        if not 0.0 < self.lr_gamma <= 1.0:
            raise ValueError(f"DiffusionConfig.lr_gamma must be in (0, 1], got {self.lr_gamma}")
        if self.num_steps < 0 or self.ema_start < 0:
            raise ValueError(f"DiffusionConfig.num_steps and ema_start must be >= 0, got {self.num_steps}, {self.ema_start}")


# ---------------------------------------------------------------------------------------------
# The denoiser.


def timestep_embedding(t: Int[ArrayLike, " b"], dim: int, max_period: float = 10000.0) -> Float[Array, "b dim"]:
    """Returns the sinusoidal embedding `[cos(t w_i), sin(t w_i)]`, `w_i = max_period^(-i / (dim/2))`."""
    half = dim // 2
    freqs = jnp.exp(-math.log(max_period) * jnp.arange(half, dtype=jnp.float32) / half)
    args = jnp.asarray(t, jnp.float32)[:, None] * freqs[None]
    emb = jnp.concatenate([jnp.cos(args), jnp.sin(args)], axis=-1)
    return jnp.pad(emb, ((0, 0), (0, dim % 2)))


class ZeroDense(nn.Module):
    """A dense layer initialised to zero (the release's `zero_module`): the block it closes starts as the identity."""

    features: int
    precision: str = "float32"

    @nn.compact
    def __call__(self, x):
        kernel = self.param("kernel", nn.initializers.zeros_init(), (x.shape[-1], self.features), jnp.float32)
        bias = self.param("bias", nn.initializers.zeros_init(), (self.features,), jnp.float32)
        return matmul(x, kernel, self.precision) + bias


class Stylization(nn.Module):
    """Returns `out(dropout(silu(LN(h) * (1 + scale) + shift)))`, `(scale, shift)` a linear map of `silu(emb)` (FiLM)."""

    latent: int
    dropout: float
    precision: str = "float32"

    @nn.compact
    def __call__(self, h, emb, deterministic: bool):
        ss = Dense(2 * self.latent, precision=self.precision, name="emb")(nn.silu(emb))[:, None]
        scale, shift = jnp.split(ss, 2, axis=-1)
        h = nn.LayerNorm(epsilon=1e-5, name="norm")(h) * (1.0 + scale) + shift
        h = nn.Dropout(self.dropout)(nn.silu(h), deterministic=deterministic)
        return ZeroDense(self.latent, self.precision, name="out")(h)


class NoBiasDense(nn.Module):
    """A dense layer without bias (attention's query, key and value), its kernel initialised as `Dense`'s (the release's nn.Linear)."""

    features: int
    precision: str = "float32"

    @nn.compact
    def __call__(self, x):
        k_init, _ = initializers("torch", x.shape[-1])
        kernel = self.param("kernel", k_init, (x.shape[-1], self.features), jnp.float32)
        return matmul(x, kernel, self.precision)


class Block(nn.Module):
    """One transformer block over the coefficients: self-attention, then a feed-forward layer, each closed by `Stylization`."""

    latent: int
    ff: int
    num_heads: int
    dropout: float
    precision: str = "float32"

    @nn.compact
    def __call__(self, h: Float[Array, "b n c"], emb: Float[Array, "b c"], deterministic: bool):
        b, n, c = h.shape
        nh, mm = self.num_heads, self.precision
        hn = nn.LayerNorm(epsilon=1e-5, name="attn_norm")(h)
        q, k, v = (NoBiasDense(c, precision=mm, name=w)(hn).reshape(b, n, nh, c // nh) for w in ("query", "key", "value"))
        w = jax.nn.softmax(jnp.einsum("bnhd,bmhd->bnmh", q, k) / math.sqrt(c // nh), axis=2)
        w = nn.Dropout(self.dropout)(w, deterministic=deterministic)
        y = jnp.einsum("bnmh,bmhd->bnhd", w, v).reshape(b, n, c)
        h = h + Stylization(c, self.dropout, mm, name="attn_style")(y, emb, deterministic)
        y = nn.gelu(Dense(self.ff, precision=mm, name="ff_in")(h), approximate=False)
        y = ZeroDense(c, mm, name="ff_out")(nn.Dropout(self.dropout)(y, deterministic=deterministic))
        return h + Stylization(c, self.dropout, mm, name="ff_style")(y, emb, deterministic)


class Denoiser(nn.Module):
    """Returns the predicted noise `(b, n_dct, dim)` of noisy coefficients `x` at timesteps `t` given the condition `cond`.

    `keep (b,)` is 1 where the condition is used and 0 where it is dropped (classifier-free training):
    the condition's embedding is added to the timestep's only where `keep` is 1.
    """

    dim: int
    n_dct: int
    latent: int = 128
    ff: int = 256
    num_layers: int = 4
    num_heads: int = 4
    dropout: float = 0.2
    execution: Execution = Execution()  # how it runs (its products' precision): nn/execution.py

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "b n d"], t: Int[ArrayLike, " b"], cond: Float[ArrayLike, "b n d"],
                 keep: Float[ArrayLike, " b"], deterministic: bool = True) -> Float[Array, "b n d"]:
        b, n, _ = x.shape
        c, mm = self.latent, self.execution.precision
        emb = Dense(c, precision=mm, name="time_in")(timestep_embedding(t, c))
        emb = Dense(c, precision=mm, name="time_out")(nn.silu(emb))
        emb = emb + jnp.asarray(keep, jnp.float32)[:, None] * Dense(c, precision=mm, name="cond_embed")(
            jnp.reshape(cond, (b, -1)))
        seq = self.param("sequence_embedding", nn.initializers.normal(1.0), (self.n_dct, c), jnp.float32)
        h = Dense(c, precision=mm, name="joint_embed")(x) + seq[None, :n]
        skips = []
        for i in range(self.num_layers):
            block = Block(c, self.ff, self.num_heads, self.dropout, mm, name=f"block_{i}")
            if i < self.num_layers // 2:
                skips.append(h)
                h = block(h, emb, deterministic)
            else:
                h = block(h, emb, deterministic) + skips.pop()
        return ZeroDense(self.dim, mm, name="out")(h)


def denoiser(c: DiffusionConfig, dim: int, execution: Execution = Execution()) -> Denoiser:
    """Returns the denoiser a `DiffusionConfig` describes for `dim`-dimensional frames, run as `execution` says."""
    return Denoiser(dim=dim, n_dct=c.n_dct, latent=c.latent, ff=c.ff, num_layers=c.num_layers, num_heads=c.num_heads,
                    dropout=c.dropout, execution=execution)


# ---------------------------------------------------------------------------------------------
# The forward process and its schedule.


def cosine_betas(noise_steps: int, s: float = 0.008) -> np.ndarray:
    """Returns the cosine schedule's betas (Nichol & Dhariwal 2021, Eq. (17)): `abar(t) = cos((t/T + s)/(1 + s) pi/2)^2`."""
    t = np.linspace(0.0, 1.0, noise_steps + 1)
    abar = np.cos((t + s) / (1 + s) * np.pi / 2) ** 2
    abar = abar / abar[0]
    return np.clip(1.0 - abar[1:] / abar[:-1], 0.0, 0.999)


def linear_betas(noise_steps: int, start: float = 1e-4, end: float = 0.02) -> np.ndarray:
    """Returns DDPM's linear betas `(noise_steps,)` from `start` to `end`, scaled by 1000 / T as the release does."""
    scale = 1000.0 / noise_steps
    return np.linspace(scale * start, scale * end, noise_steps)


def schedule(kind: str, noise_steps: int) -> Float[Array, " T"]:
    """Returns `abar_t = prod_{s <= t} (1 - beta_s)` for t = 0..T-1 (float32) of the schedule `kind`."""
    if kind not in SCHEDULES:
        raise ValueError(f"schedule must be one of {SCHEDULES}, got {kind!r}")
    betas = cosine_betas(noise_steps) if kind == "cosine" else linear_betas(noise_steps)
    return jnp.asarray(np.cumprod(1.0 - betas), jnp.float32)


def ddim_timesteps(noise_steps: int, sampling_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Returns `(t, t_prev)`, the DDIM sub-sequence `1, 1 + T/S, ...` and each step's previous level (0 first)."""
    if noise_steps % sampling_steps or sampling_steps >= noise_steps:
        raise ValueError(f"sampling_steps ({sampling_steps}) must divide noise_steps ({noise_steps}) and be smaller")
    t = np.arange(0, noise_steps, noise_steps // sampling_steps) + 1
    return t, np.concatenate([[0], t[:-1]])


def pad_last(x: Float[ArrayLike, "... t_his d"], t_total: int) -> Float[Array, "... t_total d"]:
    """Returns the observed frames followed by the last observed pose repeated up to `t_total` frames (HumanMAC's padding)."""
    x = jnp.asarray(x)
    last = jnp.broadcast_to(x[..., -1:, :], (*x.shape[:-2], t_total - x.shape[-2], x.shape[-1]))
    return jnp.concatenate([x, last], axis=-2)


def condition(x: Float[ArrayLike, "b t_his d"], t_total: int, n_dct: int) -> Float[Array, "b n d"]:
    """Returns the condition: the first `n_dct` DCT coefficients of the padded observation (`pad_last`)."""
    return dct(pad_last(x, t_total), n_dct)


def q_sample(abar: Float[Array, " T"], x0, t: Int[ArrayLike, " b"], eps):
    """Returns `x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps` (DDPM Eq. (4)), `t (b,)` indexing the batch."""
    a = abar[t][:, None, None]
    return jnp.sqrt(a) * x0 + jnp.sqrt(1.0 - a) * eps


def diffusion_loss(model: Denoiser, params, batch: Float[ArrayLike, "b t d"], key: jax.Array, *, t_his: int,
                   abar: Float[Array, " T"], cond_drop: float):
    """Returns `(loss, metrics)`: DDPM's noise-prediction loss `mean ||eps - eps_theta(x_t, t, c)||^2` on whole windows.

    `t` is uniform on 1..T-1 (the release's range), and the condition is dropped for each window
    with probability `cond_drop`.
    """
    batch = jnp.asarray(batch)
    b, t_total = batch.shape[:2]
    x0 = dct(batch, model.n_dct)
    cond = condition(batch[:, :t_his], t_total, model.n_dct)
    k_t, k_eps, k_drop, k_dropout = jax.random.split(key, 4)
    t = jax.random.randint(k_t, (b,), 1, abar.shape[0])
    eps = jax.random.normal(k_eps, x0.shape)
    keep = (jax.random.uniform(k_drop, (b,)) >= cond_drop).astype(jnp.float32)
    pred = model.apply(params, q_sample(abar, x0, t, eps), t, cond, keep, deterministic=False, rngs={"dropout": k_dropout})
    mse = jnp.mean((pred - eps) ** 2)
    return mse, {"mse": mse, "cond_kept": jnp.mean(keep)}


# ---------------------------------------------------------------------------------------------
# Sampling: DDIM with DCT completion.


def completion_mask(t_total: int, dim: int, frames: int) -> Float[Array, "t_total d"]:
    """Returns the completion mask: 1 on the first `frames` frames (every coordinate), 0 elsewhere."""
    if not 0 <= frames <= t_total:
        raise ValueError(f"completion_mask: frames must be in [0, {t_total}], got {frames}")
    return jnp.broadcast_to((jnp.arange(t_total) < frames)[:, None], (t_total, dim)).astype(jnp.float32)


def ddim_sample(denoise, x_T: Float[Array, "b n d"], cond: Float[Array, "b n d"], key: jax.Array, *,
                abar: Float[Array, " T"], t_seq, t_prev, t_total: int, mask: Float[Array, "t d"] | None):
    """Returns the DCT coefficients `x_0 (b, n, d)` that DDIM (sigma = 0) reaches from `x_T`, in one `lax.scan`.

    `denoise(x, t)` is the noise prediction at the scalar timestep `t`. Each step (DDIM Eq. (12)):
    `x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)`, `x_prev = sqrt(abar_prev) x0_hat + sqrt(1 - abar_prev) eps`.
    With `mask`, DCT completion follows (HumanMAC Eq. (6)-(7)): the condition noised to `abar_prev`
    with fresh noise (`normal(fold_in(key, i))` at DDIM index `i`), both signals back in time, the
    masked frames from the condition and the rest from the sample, then back to DCT.
    """
    n = x_T.shape[-2]

    def step(x, inp):
        t, tp, i = inp
        a, ap = abar[t], abar[tp]
        eps = denoise(x, t)
        x0 = (x - jnp.sqrt(1.0 - a) * eps) / jnp.sqrt(a)
        x = jnp.sqrt(ap) * x0 + jnp.sqrt(1.0 - ap) * eps
        if mask is not None:
            known = jnp.sqrt(ap) * cond + jnp.sqrt(1.0 - ap) * jax.random.normal(jax.random.fold_in(key, i), x.shape)
            x = dct(mask * idct(known, t_total) + (1.0 - mask) * idct(x, t_total), n)
        return x, None

    idx = jnp.arange(len(t_seq))[::-1]
    xs = (jnp.asarray(t_seq)[::-1], jnp.asarray(t_prev)[::-1], idx)
    x, _ = jax.lax.scan(step, x_T, xs)
    return x


def _layer_norm(x, p, eps: float = 1e-5):
    # Both moments in one pass over x (flax's LayerNorm computes its variance the same way).
    mu, mu2 = jnp.mean(x, axis=-1, keepdims=True), jnp.mean(x * x, axis=-1, keepdims=True)
    return (x - mu) * jax.lax.rsqrt(jnp.maximum(mu2 - mu * mu, 0.0) + eps) * p["scale"] + p["bias"]


def _dense(x, p, mm):
    return matmul(x, p["kernel"], mm) + p["bias"]


class _Folded(NamedTuple):
    """The denoiser's weights regrouped for `_trunk`: per block the query/key/value kernels side by side."""

    blocks: tuple  # per block: (attn_norm, qkv kernel (c, 3c), attn_style's norm and out, ff_in, ff_out, ff_style's)
    film: tuple  # (kernel (c, F), bias (F,)): every Stylization's `emb` layer side by side, F = 4 c per block


def _fold(p: dict, num_layers: int) -> _Folded:
    blocks, film_k, film_b = [], [], []
    for i in range(num_layers):
        q = p[f"block_{i}"]
        qkv = jnp.concatenate([q[w]["kernel"] for w in ("query", "key", "value")], axis=1)
        blocks.append((q["attn_norm"], qkv, q["attn_style"]["norm"], q["attn_style"]["out"], q["ff_in"], q["ff_out"],
                       q["ff_style"]["norm"], q["ff_style"]["out"]))
        for st in ("attn_style", "ff_style"):
            film_k.append(q[st]["emb"]["kernel"])
            film_b.append(q[st]["emb"]["bias"])
    return _Folded(tuple(blocks), (jnp.concatenate(film_k, axis=1), jnp.concatenate(film_b)))


def _trunk(p: dict, w: _Folded, x: Float[Array, "n k b d"], film: Float[Array, "#k b f"], num_heads: int,
           mm: str) -> Float[Array, "n k b d"]:
    """Returns `Denoiser`'s noise prediction from the Stylization layers' precomputed `(scale, shift)` inputs `film`.

    The same network as `Denoiser.__call__` (tested against it), laid out coefficient-major: the
    rows `(k, b)` of every coefficient are one batch of every product, and attention runs per head on
    `(rows, heads, n, d_head)` operands.
    """
    n, kk, b, _ = x.shape
    c = p["joint_embed"]["kernel"].shape[1]
    nh, dh = num_heads, c // num_heads
    h = _dense(x, p["joint_embed"], mm) + p["sequence_embedding"][:n, None, None]
    num_layers = len(w.blocks)
    skips = []
    for i, (an, qkv_k, a_norm, a_out, ff_in, ff_out, f_norm, f_out) in enumerate(w.blocks):
        f = film[..., 4 * c * i: 4 * c * (i + 1)]
        h_in = h
        qkv = matmul(_layer_norm(h, an), qkv_k, mm).reshape(n, kk * b, 3, nh, dh)
        q, k, v = (qkv[:, :, j].transpose(1, 2, 0, 3) for j in range(3))  # (rows, nh, n, dh)
        att = jax.nn.softmax(jnp.einsum("rhnd,rhmd->rhnm", q, k) / math.sqrt(dh), axis=-1)
        y = jnp.einsum("rhnm,rhmd->rhnd", att, v).transpose(2, 0, 1, 3).reshape(n, kk, b, c)
        y = nn.silu(_layer_norm(y, a_norm) * (1.0 + f[..., :c]) + f[..., c:2 * c])
        h = h + _dense(y, a_out, mm)
        y = _dense(nn.gelu(_dense(h, ff_in, mm), approximate=False), ff_out, mm)
        y = nn.silu(_layer_norm(y, f_norm) * (1.0 + f[..., 2 * c:3 * c]) + f[..., 3 * c:])
        h = h + _dense(y, f_out, mm)
        if i < num_layers // 2:
            skips.append(h_in)
        else:
            h = h + skips.pop()
    return _dense(h, p["out"], mm)


# The folded sampler's default chunk of K, in rows (samples x windows x coefficients) of its products:
# measured on a 2-core CPU at batch 64, K = 50 (960 rows a sample), chunks of 10 samples (9,600 rows)
# ran 1.15x faster than all 50 at once and 1.8x faster than one at a time.
CHUNK_ROWS = 10_000


def sample(model: Denoiser, params, x: Float[ArrayLike, "b t_his d"], key: jax.Array, k: int, *, t_pred: int,
           abar: Float[Array, " T"], sampling_steps: int, complete_frames: int | None = None,
           cond_keep: float = 1.0, k_chunk: int | None = None,
           devices: Sequence[jax.Device] | None = None) -> Float[Array, "b k t_pred d"]:
    """Returns K futures per window: DDIM (sigma = 0) with DCT completion, one `lax.scan` over the steps.

    The futures of `sample_reference` (`ddim_sample` of the Flax denoiser vmapped over K; tested equal
    to float32 tolerance), computed with the K samples folded into the batch of every product and
    what does not change across steps computed once before the scan: the timestep embeddings of the
    fixed step sequence, the condition's embedding, each step's two DDIM coefficients, and the DCT
    completion as two `(n, n)` matrices, `A = C M C^T` and `C (1 - M) C^T` (`C` the DCT, `M` the
    mask), so a step's completion is `A (sqrt(abar_prev) cond + sqrt(1 - abar_prev) z) + C (1 - M) C^T x`.
    Every Stylization's `(scale, shift)` comes from the step's embedding on the windows' rows, not K times.

    Sample k draws its start `x_T` from `split(key_k)[0]` and its completion noise from `split(key_k)[1]`,
    `key_k = split(key, k)[k]`. `cond_keep < 1` (`DiffusionConfig.test_cond_keep`): sample k is conditioned, for every
    window of the batch, with probability `cond_keep` (drawn from `split(key_k, 3)[2]`) and denoised unconditioned otherwise.

    Args:
        model: the denoiser.
        params: its trained variables.
        x: observed frames `(b, t_his, D)`, metres, root-relative.
        key: a `jax.random` key.
        k: the number of futures K.
        t_pred: the number of future frames.
        abar: the `(T,)` cumulative products of `1 - beta` of the training noise schedule.
        sampling_steps: DDIM steps (fewer is faster and less accurate: the Results page plots it).
        complete_frames: observed frames put back at every step (None: all `t_his`; 0: no completion).
        cond_keep: the probability that a sample is conditioned on `x` (1: always).
        k_chunk: the K samples run this many at a time (a divisor of K), each chunk its own scan over
            the steps, so a large batch's activations stay in cache; the futures are the same. None:
            the largest divisor of K whose chunk holds at most `CHUNK_ROWS` coefficient rows. With
            `devices`, a divisor of each device's share of K.
        devices: split the K samples evenly over these devices (`jax.shard_map`), each device running
            its share's scan at the same time; the futures are the same (sample k keeps its key). None:
            one device. On a CPU, `XLA_FLAGS=--xla_force_host_platform_device_count=N` (set before jax
            starts) gives N host devices: each runs its own stream of XLA operations, which uses the
            cores that one stream of small operations leaves idle (Benchmarks page, "Diffusion sampling").

    Returns:
        `(b, K, t_pred, D)` futures.
    """
    keys = jax.random.split(key, k)
    kw = dict(t_pred=t_pred, abar=abar, sampling_steps=sampling_steps, complete_frames=complete_frames,
              cond_keep=cond_keep, k_chunk=k_chunk)
    if devices is None or len(devices) == 1:
        return _sample_keys(model, params, x, keys, **kw)
    nd = len(devices)
    if k % nd:
        raise ValueError(f"sample: K ({k}) must be a multiple of the number of devices ({nd})")
    if k_chunk is not None and (k // nd) % k_chunk:
        raise ValueError(f"sample: k_chunk ({k_chunk}) must divide each device's share of K ({k} / {nd} devices = {k // nd})")
    mesh = jax.sharding.Mesh(np.asarray(devices), ("k",))
    spec = jax.sharding.PartitionSpec
    shard = jax.shard_map(lambda p, xx, kk: _sample_keys(model, p, xx, kk, **kw), mesh=mesh,
                          in_specs=(spec(), spec(), spec("k")), out_specs=spec(None, "k"))
    return shard(params, jnp.asarray(x), keys)


def _sample_keys(model: Denoiser, params, x: Float[ArrayLike, "b t_his d"], keys: jax.Array, *, t_pred: int,
                 abar: Float[Array, " T"], sampling_steps: int, complete_frames: int | None, cond_keep: float,
                 k_chunk: int | None) -> Float[Array, "b k t_pred d"]:
    """Returns `sample`'s futures for the samples of `keys` (`(K,)`, sample k's own key)."""
    k = keys.shape[0]
    x = jnp.asarray(x)
    b, t_his, d = x.shape
    t_total = t_his + t_pred
    n, c, mm = model.n_dct, model.latent, model.execution.precision
    if k_chunk is None:
        k_chunk = max([j for j in range(1, k + 1) if k % j == 0 and j * b * n <= CHUNK_ROWS] or [1])
    if k % k_chunk:
        raise ValueError(f"sample: k_chunk ({k_chunk}) must divide k ({k})")
    p = params["params"]
    w = _fold(p, model.num_layers)
    cond = condition(x, t_total, n)
    frames = t_his if complete_frames is None else complete_frames
    t_seq, t_prev = ddim_timesteps(abar.shape[0], sampling_steps)
    t_seq, t_prev = t_seq[::-1].copy(), t_prev[::-1].copy()  # the scan's order: from noise to data
    a, ap = abar[t_seq], abar[t_prev]
    # DDIM Eq. (12), sigma = 0: x_prev = sqrt(ap / a) x + (sqrt(1 - ap) - sqrt(ap (1 - a) / a)) eps.
    c_x, c_eps = jnp.sqrt(ap / a), jnp.sqrt(1.0 - ap) - jnp.sqrt(ap * (1.0 - a) / a)

    # What a step reads of the fixed step sequence, one row per step: the timestep embedding and the
    # DDIM and completion coefficients. A step takes its row as a one-hot product: XLA:CPU fuses a
    # scan's per-step slice into the elementwise loops that read it and recomputes the dynamic index
    # per element (6-8x slower loops).
    time = _dense(nn.silu(_dense(timestep_embedding(jnp.asarray(t_seq), c), p["time_in"], mm)), p["time_out"], mm)
    table = jnp.concatenate([time, jnp.stack([c_x, c_eps, jnp.sqrt(ap), jnp.sqrt(1.0 - ap)], axis=1)], axis=1)
    cond_e = _dense(cond.reshape(b, -1), p["cond_embed"], mm)
    film_of = lambda emb: matmul(nn.silu(emb), w.film[0], mm) + w.film[1]  # noqa: E731

    dmat = dct_matrix(t_total, n)
    m = (jnp.arange(t_total) < frames).astype(jnp.float32)
    keep_mat = (dmat * m) @ dmat.T  # C M C^T
    free_mat = (dmat * (1.0 - m)) @ dmat.T  # C (1 - M) C^T
    known = jnp.einsum("ij,bjd->ibd", keep_mat, cond)[:, None]  # C M C^T cond, (n, 1, b, d)

    if cond_keep < 1.0:
        split3 = jax.vmap(lambda kk: jax.random.split(kk, 3))(keys)
        k0, k1, k2 = split3[:, 0], split3[:, 1], split3[:, 2]
        keep = jax.vmap(lambda kk: jax.random.uniform(kk) < cond_keep)(k2)
    else:
        split2 = jax.vmap(jax.random.split)(keys)
        k0, k1 = split2[:, 0], split2[:, 1]
        keep = None
    x_T = jax.vmap(lambda kk: jax.random.normal(kk, cond.shape))(k0)  # (k, b, n, d)

    def chunk(args):
        x_T, k1, keep = args

        def step(xt, i):
            row = jax.nn.one_hot(i, len(t_seq), dtype=table.dtype) @ table
            time_i, (cx, ce, sa, sn) = row[:c], row[c:]
            f = film_of(time_i + cond_e)[None]  # (1, b, F)
            if keep is not None:
                f = jnp.where(keep[:, None, None], f, film_of(time_i))
            eps = _trunk(p, w, xt, f, model.num_heads, mm)
            xt = cx * xt + ce * eps
            if frames:
                # The noise of DDIM index S - 1 - i (the scan runs from the last index down).
                z = jax.vmap(lambda kk: jax.random.normal(jax.random.fold_in(kk, len(t_seq) - 1 - i), cond.shape))(k1)
                xt = ((free_mat @ xt.reshape(n, -1)).reshape(xt.shape) + sa * known
                      + sn * jnp.einsum("ij,kbjd->ikbd", keep_mat, z))
            return xt, None

        x0, _ = jax.lax.scan(step, jnp.moveaxis(x_T, 2, 0), jnp.arange(len(t_seq)))
        return x0  # (n, k, b, d)

    n_chunks = k // k_chunk
    split = lambda a: None if a is None else a.reshape(n_chunks, k_chunk, *a.shape[1:])  # noqa: E731
    if n_chunks == 1:
        x0 = chunk((x_T, k1, keep))
    else:
        x0 = jnp.moveaxis(jax.lax.map(chunk, (split(x_T), split(k1), split(keep))), 0, 1).reshape(n, k, b, d)
    return jnp.einsum("ct,ckbd->bktd", dmat[:, t_his:], x0)


def sample_reference(model: Denoiser, params, x: Float[ArrayLike, "b t_his d"], key: jax.Array, k: int, *,
                     t_pred: int, abar: Float[Array, " T"], sampling_steps: int, complete_frames: int | None = None,
                     cond_keep: float = 1.0) -> Float[Array, "b k t_pred d"]:
    """Returns `sample`'s futures the readable way: `ddim_sample` of the Flax denoiser, vmapped over the K samples.

    The definition `sample` is tested against; the arguments and the random draws are `sample`'s.
    """
    x = jnp.asarray(x)
    b, t_his, d = x.shape
    t_total = t_his + t_pred
    cond = condition(x, t_total, model.n_dct)
    frames = t_his if complete_frames is None else complete_frames
    mask = completion_mask(t_total, d, frames) if frames else None
    t_seq, t_prev = ddim_timesteps(abar.shape[0], sampling_steps)
    ones = jnp.ones((b,), jnp.float32)

    def one(key_k):
        if cond_keep < 1.0:
            k0, k1, k2 = jax.random.split(key_k, 3)
            keep = ones * (jax.random.uniform(k2) < cond_keep).astype(jnp.float32)
        else:
            (k0, k1), keep = jax.random.split(key_k), ones

        def denoise(xt, t):
            return model.apply(params, xt, jnp.full((b,), t), cond, keep)

        x0 = ddim_sample(denoise, jax.random.normal(k0, cond.shape), cond, k1, abar=abar, t_seq=t_seq, t_prev=t_prev,
                         t_total=t_total, mask=mask)
        return idct(x0, t_total)[:, t_his:]

    return jnp.swapaxes(jax.vmap(one)(jax.random.split(key, k)), 0, 1)


# ---------------------------------------------------------------------------------------------
# EMA of the weights, as an optax transformation.


class EmaState(NamedTuple):
    """The state of the parameters' exponential moving average: the number of updates so far."""

    count: jax.Array


def ema_weights(decay: float, start: int) -> optax.GradientTransformation:
    """Returns the transformation that keeps `params["ema"]` an exponential moving average of `params["model"]`.

    For parameters `{"model": ..., "ema": ...}` (the loss reads only "model", so the updates of "ema"
    from earlier transformations are zero), the update of "ema" becomes the one that sets it to
    `decay * ema + (1 - decay) * model_new`, `model_new` the weights after this step's update; for the
    first `start` steps it sets it to `model_new` (the release's EMA: copy, then average). Chain it last.
    """

    def init(params):
        del params
        return EmaState(count=jnp.zeros((), jnp.int32))

    def update(updates, state, params=None):
        if params is None:
            raise ValueError("ema_weights needs the parameters (optax: tx.update(grads, state, params))")
        model = optax.apply_updates(params["model"], updates["model"])
        d = jnp.where(state.count < start, 0.0, decay)
        ema = jax.tree.map(lambda e, m: d * e + (1.0 - d) * m, params["ema"], model)
        return {**updates, "ema": jax.tree.map(jnp.subtract, ema, params["ema"])}, EmaState(count=state.count + 1)

    return optax.GradientTransformation(init, update)
