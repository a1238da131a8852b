"""The DCT-space diffusion predictor (HumanMAC class) in PyTorch, sampling the release's way.

The twin of jaxmotion/models/diffusion.py, layer for layer (parameters load through
`convert.diffusion_denoiser`). K futures are drawn as the release draws them: each window repeated K
times along the batch axis, and DDIM as a Python loop over the sampling steps, each step one call of
the denoiser followed by the DCT completion.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from benchmarks.torch_ref.dct import dct_matrix


def timestep_embedding(t: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, dtype=torch.float32) / half)
    args = t[:, None].float() * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], dim=-1)
    return F.pad(emb, (0, dim % 2))


class Stylization(nn.Module):
    def __init__(self, latent: int, dropout: float):
        super().__init__()
        self.emb = nn.Linear(latent, 2 * latent)
        self.norm = nn.LayerNorm(latent)
        self.drop = nn.Dropout(dropout)
        self.out = nn.Linear(latent, latent)

    def forward(self, h, emb):
        scale, shift = self.emb(F.silu(emb))[:, None].chunk(2, dim=-1)
        return self.out(self.drop(F.silu(self.norm(h) * (1 + scale) + shift)))


class Block(nn.Module):
    def __init__(self, latent: int, ff: int, num_heads: int, dropout: float):
        super().__init__()
        self.num_heads = num_heads
        self.attn_norm = nn.LayerNorm(latent)
        self.query = nn.Linear(latent, latent, bias=False)
        self.key = nn.Linear(latent, latent, bias=False)
        self.value = nn.Linear(latent, latent, bias=False)
        self.drop = nn.Dropout(dropout)
        self.attn_style = Stylization(latent, dropout)
        self.ff_in = nn.Linear(latent, ff)
        self.ff_out = nn.Linear(ff, latent)
        self.ff_style = Stylization(latent, dropout)

    def forward(self, h, emb):
        b, n, c = h.shape
        nh = self.num_heads
        hn = self.attn_norm(h)
        q, k, v = (f(hn).view(b, n, nh, c // nh) for f in (self.query, self.key, self.value))
        w = self.drop(F.softmax(torch.einsum("bnhd,bmhd->bnmh", q, k) / math.sqrt(c // nh), dim=2))
        y = torch.einsum("bnmh,bmhd->bnhd", w, v).reshape(b, n, c)
        h = h + self.attn_style(y, emb)
        y = self.ff_out(self.drop(F.gelu(self.ff_in(h))))
        return h + self.ff_style(y, emb)


class Denoiser(nn.Module):
    """`forward(x (b, n, d), t (b,), cond (b, n, d) or None)` returns the predicted noise; `cond=None` drops the condition."""

    def __init__(self, dim: int, n_dct: int, latent: int = 64, ff: int = 128, num_layers: int = 4, num_heads: int = 4,
                 dropout: float = 0.2):
        super().__init__()
        self.n_dct, self.latent, self.num_layers = n_dct, latent, num_layers
        self.time_in = nn.Linear(latent, latent)
        self.time_out = nn.Linear(latent, latent)
        self.cond_embed = nn.Linear(n_dct * dim, latent)
        self.sequence_embedding = nn.Parameter(torch.randn(n_dct, latent))
        self.joint_embed = nn.Linear(dim, latent)
        self.blocks = nn.ModuleList(Block(latent, ff, num_heads, dropout) for _ in range(num_layers))
        self.out = nn.Linear(latent, dim)

    def forward(self, x, t, cond=None):
        b, n, _ = x.shape
        emb = self.time_out(F.silu(self.time_in(timestep_embedding(t, self.latent))))
        if cond is not None:
            emb = emb + self.cond_embed(cond.reshape(b, -1))
        h = self.joint_embed(x) + self.sequence_embedding[None, :n]
        skips = []
        for i, block in enumerate(self.blocks):
            if i < self.num_layers // 2:
                skips.append(h)
                h = block(h, emb)
            else:
                h = block(h, emb) + skips.pop()
        return self.out(h)


def ddim_schedule(noise_steps: int, sampling_steps: int, s: float = 0.008) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """Returns `(abar (T,), t_seq, t_prev)`: the cosine schedule's cumulative alphas and the DDIM sub-sequence (the release's)."""
    t = np.linspace(0.0, 1.0, noise_steps + 1)
    f = np.cos((t + s) / (1 + s) * np.pi / 2) ** 2
    betas = np.clip(1.0 - f[1:] / f[:-1], 0.0, 0.999)
    seq = np.arange(0, noise_steps, noise_steps // sampling_steps) + 1
    return torch.tensor(np.cumprod(1.0 - betas), dtype=torch.float32), seq, np.concatenate([[0], seq[:-1]])


def completion_mask(t_total: int, dim: int, frames: int) -> torch.Tensor:
    """Returns the `(t_total, dim)` mask that is 1 on the first `frames` frames."""
    return (torch.arange(t_total) < frames)[:, None].expand(t_total, dim).float()


def sample_ddim(model: Denoiser, x: torch.Tensor, k: int, *, t_pred: int, n_dct: int, abar: torch.Tensor, t_seq,
                t_prev, mask: torch.Tensor | None, x_T: torch.Tensor | None = None,
                step_noise: Callable[[int], torch.Tensor] | None = None) -> torch.Tensor:
    """Returns K futures `(b, k, t_pred, d)` per window `x (b, t_his, d)`: DDIM with DCT completion, a Python loop over steps.

    The windows are repeated K times (row `w * k + j` is sample j of window w). `x_T` and `step_noise(i)`
    (the completion's noise at DDIM index i) are drawn with `torch.randn` where not given.
    """
    b, t_his, d = x.shape
    t_total = t_his + t_pred
    traj = x.repeat_interleave(k, dim=0)
    pad = torch.cat([traj, traj[:, -1:].expand(-1, t_pred, -1)], dim=1)
    c = dct_matrix(t_total, n_dct)
    traj_dct = c @ pad
    xt = torch.randn_like(traj_dct) if x_T is None else x_T
    for i in reversed(range(len(t_seq))):
        t = torch.full((b * k,), int(t_seq[i]), dtype=torch.long)
        a, ap = abar[int(t_seq[i])], abar[int(t_prev[i])]
        eps = model(xt, t, traj_dct)
        x0 = (xt - torch.sqrt(1 - a) * eps) / torch.sqrt(a)
        xt = torch.sqrt(ap) * x0 + torch.sqrt(1 - ap) * eps
        if mask is not None:
            z = torch.randn_like(traj_dct) if step_noise is None else step_noise(i)
            known = torch.sqrt(ap) * traj_dct + torch.sqrt(1 - ap) * z
            xt = c @ (mask * (c.T @ known) + (1 - mask) * (c.T @ xt))
    return (c.T @ xt)[:, t_his:].reshape(b, k, t_pred, d)
