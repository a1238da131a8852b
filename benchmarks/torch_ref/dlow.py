"""DLow (Yuan & Kitani, ECCV 2020) in PyTorch: the GRU CVAE, the Q network, samplers and both losses.

The twin of jaxmotion/models/dlow.py, layer for layer. K futures are decoded the way PyTorch code
does it: the past is encoded once and its features repeated K times along the batch axis.
"""

from __future__ import annotations

import torch
from torch import nn

from benchmarks.torch_ref.layers import GRU, MLP


class DLowCVAE(nn.Module):
    """The DLow CVAE over `(batch, time, dim)`; `forward(x, y, eps)` returns `(y_rec, mu, logvar)`."""

    def __init__(self, dim: int, horizon: int, nz: int = 128, nh_rnn: int = 128, nh_mlp: tuple[int, ...] = (300, 200)):
        super().__init__()
        self.dim, self.horizon, self.nz = dim, horizon, nz
        self.x_rnn = GRU(dim, nh_rnn)
        self.e_rnn = GRU(dim, nh_rnn)
        self.e_mlp = MLP(2 * nh_rnn, nh_mlp)
        self.e_mu = nn.Linear(nh_mlp[-1], nz)
        self.e_logvar = nn.Linear(nh_mlp[-1], nz)
        self.drnn_mlp = MLP(nh_rnn, tuple(nh_mlp) + (nh_rnn,))
        self.d_cell = nn.GRUCell(nh_rnn + nz + dim, nh_rnn)
        self.d_mlp = MLP(nh_rnn, nh_mlp)
        self.d_out = nn.Linear(nh_mlp[-1], dim)

    def encode_x(self, x: torch.Tensor) -> torch.Tensor:
        """Returns the last hidden state `(b, h)` of the past encoder GRU."""
        return self.x_rnn(x)[:, -1]

    def encode(self, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Returns `(mu, logvar)` of q(z | X, Y)."""
        h = self.e_mlp(torch.cat([self.encode_x(x), self.e_rnn(y)[:, -1]], dim=-1))
        return self.e_mu(h), self.e_logvar(h)

    def decode(self, x: torch.Tensor, z: torch.Tensor, h_x: torch.Tensor | None = None) -> torch.Tensor:
        """Returns the future `(b, horizon, dim)` decoded autoregressively from latents `z` (b, nz)."""
        if h_x is None:
            h_x = self.encode_x(x)
        cond = torch.cat([h_x, z], dim=-1)
        h, y = self.drnn_mlp(h_x), x[:, -1]
        ys = []
        for _ in range(self.horizon):
            h = self.d_cell(torch.cat([cond, y], dim=-1), h)
            y = self.d_out(self.d_mlp(h))
            ys.append(y)
        return torch.stack(ys, dim=1)

    def forward(self, x, y, eps: torch.Tensor | None = None):
        """Returns `(y_rec, mu, logvar)` with z = mu + std * eps (z = mu when `eps` is None)."""
        mu, logvar = self.encode(x, y)
        z = mu if eps is None else mu + torch.exp(0.5 * logvar) * eps
        return self.decode(x, z), mu, logvar


class DLowQ(nn.Module):
    """DLow's Q network ("NFDiag"): returns `(z (b, nk, nz), a, b)` with `z_k = a_k * eps + b_k`."""

    def __init__(self, dim: int, nz: int = 128, nk: int = 50, nh_rnn: int = 128, nh_mlp: tuple[int, ...] = (1024, 512)):
        super().__init__()
        self.nz, self.nk = nz, nk
        self.x_rnn = GRU(dim, nh_rnn)
        self.mlp = MLP(nh_rnn, nh_mlp)
        self.head_A = nn.Linear(nh_mlp[-1], nz * nk)
        self.head_b = nn.Linear(nh_mlp[-1], nz * nk)

    def forward(self, x: torch.Tensor, eps: torch.Tensor):
        h = self.mlp(self.x_rnn(x)[:, -1])
        a = self.head_A(h).reshape(-1, self.nk, self.nz)
        b = self.head_b(h).reshape(-1, self.nk, self.nz)
        return a * eps[:, None, :] + b, a, b


def decode_k(cvae: DLowCVAE, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """Returns the K futures `(b, k, t_pred, d)` for latents `z (b, k, nz)`; the past is encoded once."""
    b, k, _ = z.shape
    h_x = cvae.encode_x(x).repeat_interleave(k, dim=0)
    ys = cvae.decode(x.repeat_interleave(k, dim=0), z.reshape(b * k, -1), h_x)
    return ys.reshape(b, k, *ys.shape[1:])


def sample_prior(cvae: DLowCVAE, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """Returns K futures for latents `z (b, k, nz)` drawn by the caller from N(0, I): the CVAE baseline."""
    return decode_k(cvae, x, z)


def sample_dlow(cvae: DLowCVAE, q: DLowQ, x: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
    """Returns DLow's nk futures for one noise draw `eps (b, nz)` per window (DLow Eq. (4))."""
    z, _, _ = q(x, eps)
    return decode_k(cvae, x, z)


def kld_normal(mu, logvar):
    return -0.5 * torch.sum(1.0 + logvar - mu**2 - torch.exp(logvar), dim=-1)


def kld_affine(a, b):
    var = a**2
    return -0.5 * torch.sum(1.0 + torch.log(var) - b**2 - var, dim=-1)


def dlow_diversity(y: torch.Tensor, d_scale: float) -> torch.Tensor:
    """Returns mean over windows of mean_{i<j} exp(-||y_i - y_j||^2 / d_scale) for `y (b, k, ...)` (DLow Eq. (9))."""
    b, k = y.shape[:2]
    y = y.reshape(b, k, -1)
    sq = torch.sum(y**2, dim=-1)
    d2 = torch.clamp(sq[:, :, None] + sq[:, None, :] - 2.0 * y @ y.transpose(1, 2), min=0.0)
    iu = torch.triu_indices(k, k, 1)
    return torch.mean(torch.exp(-d2[:, iu[0], iu[1]] / d_scale))


def cvae_loss(cvae: DLowCVAE, batch: torch.Tensor, eps: torch.Tensor, *, t_his: int, beta: float, lambda_v: float):
    """Returns `(loss, metrics)`: jaxmotion.models.dlow.cvae_loss with the noise `eps (b, nz)` given."""
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = cvae(x, y, eps)
    b = batch.shape[0]
    recon = torch.sum((y_rec - y) ** 2) / b
    jump = torch.sum((x[:, -1] - y_rec[:, 0]) ** 2) / b
    kld = torch.sum(kld_normal(mu, logvar)) / b
    return recon + lambda_v * jump + beta * kld, {"recon": recon, "jump": jump, "kld": kld}


def dlow_loss(q: DLowQ, cvae: DLowCVAE, batch, eps, *, t_his: int, d_scale: float, lambda_j: float,
              lambda_recon: float, lambda_kl: float):
    """Returns `(loss, metrics)`: jaxmotion.models.dlow.dlow_loss (DLow Eq. (8)-(10)) with `eps (b, nz)` given."""
    x, y = batch[:, :t_his], batch[:, t_his:]
    z, a, b = q(x, eps)
    y_g = decode_k(cvae, x, z)
    kld = torch.mean(kld_affine(a, b))
    div = dlow_diversity(y_g, d_scale)
    recon = torch.mean(torch.amin(torch.sum((y_g - y[:, None]) ** 2, dim=(-2, -1)), dim=1))
    loss = lambda_kl * kld + lambda_j * div + lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}
