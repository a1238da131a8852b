"""MOJO (Zhang, Black & Tang, CVPR 2021) in PyTorch: the CVAE with a latent DCT space and per-band DLow.

The twin of jaxmotion/models/mojo.py (its defaults: DCT latent, residual decoder, MOJO's Eq. (1)
loss, a Q network whose GRU + MLP trunk is shared by the L lowest bands). Noise enters as tensors
so that both frameworks can be fed the same draws.
"""

from __future__ import annotations

import torch
from torch import nn

from benchmarks.torch_ref.dct import dct, idct
from benchmarks.torch_ref.dlow import dlow_diversity, kld_normal
from benchmarks.torch_ref.layers import GRU, MLP


class MojoCVAE(nn.Module):
    """MOJO's CVAE; `forward(x, y, eps)` returns `(y_rec, mu, logvar)` with `mu (b, n_bands, nz)`."""

    def __init__(self, dim: int, horizon: int, nz: int = 16, nh_rnn: int = 128, nh_mlp: tuple[int, ...] = (300, 200),
                 latent: str = "dct", residual: bool = True):
        super().__init__()
        self.dim, self.horizon, self.nz, self.latent, self.residual = dim, horizon, nz, latent, residual
        self.n_bands = horizon if latent == "dct" else 1
        self.x_rnn = GRU(dim, nh_rnn)
        self.e_rnn = GRU(dim, nh_rnn)
        self.e_mlp = MLP(2 * nh_rnn, nh_mlp)
        self.e_mu = nn.Linear(nh_mlp[-1], nz)
        self.e_logvar = nn.Linear(nh_mlp[-1], nz)
        self.drnn_mlp = MLP(nh_rnn, tuple(nh_mlp) + (nh_rnn,))
        self.d_cell = nn.GRUCell(nh_rnn + nz + dim, nh_rnn)
        self.d_mlp = MLP(nh_rnn, nh_mlp)
        self.d_out = nn.Linear(nh_mlp[-1], dim)

    def encode_x(self, x):
        return self.x_rnn(x)[:, -1]

    def encode(self, x, y):
        """Returns `(mu, logvar)`, one `nz` Gaussian per DCT band of `[h_x, h_y,t]` (MOJO Sec. 3.3)."""
        h_x = self.encode_x(x)
        h_y = self.e_rnn(y)
        if self.latent == "dct":
            h = dct(torch.cat([h_x[:, None].expand(-1, h_y.shape[1], -1), h_y], dim=-1))
        else:
            h = torch.cat([h_x, h_y[:, -1]], dim=-1)[:, None]
        h = self.e_mlp(h)
        return self.e_mu(h), self.e_logvar(h)

    def latent_to_time(self, z):
        if self.latent == "dct":
            return idct(z, self.horizon)
        return z.expand(z.shape[0], self.horizon, z.shape[-1])

    def decode(self, x, z, h_x=None):
        """Returns the future `(b, horizon, dim)` for band latents `z (b, n_bands, nz)`."""
        if h_x is None:
            h_x = self.encode_x(x)
        z_t = self.latent_to_time(z)
        h, y = self.drnn_mlp(h_x), x[:, -1]
        ys = []
        for t in range(self.horizon):
            h = self.d_cell(torch.cat([h_x, z_t[:, t], y], dim=-1), h)
            out = self.d_out(self.d_mlp(h))
            y = out + y if self.residual else out
            ys.append(y)
        return torch.stack(ys, dim=1)

    def forward(self, x, y, eps=None):
        mu, logvar = self.encode(x, y)
        z = mu if eps is None else mu + torch.exp(0.5 * logvar) * eps
        return self.decode(x, z), mu, logvar


class MojoQ(nn.Module):
    """Per-band DLow with a shared trunk: returns `(z (b, nk, L, nz), a, b)`, `z_k = exp(a_k / 2) eps + b_k`."""

    def __init__(self, dim: int, nz: int, nk: int, n_low: int, nh_rnn: int = 128, nh_mlp: tuple[int, ...] = (1024, 512)):
        super().__init__()
        self.nz, self.nk, self.n_low = nz, nk, n_low
        self.x_rnn = GRU(dim, nh_rnn)
        self.mlp = MLP(nh_rnn, nh_mlp)
        self.head_A = nn.Linear(nh_mlp[-1], n_low * nk * nz)
        self.head_b = nn.Linear(nh_mlp[-1], n_low * nk * nz)

    def forward(self, x, eps):
        """`eps (b, L, nz)`: one draw per window and band, shared by the nk maps."""
        h = self.mlp(self.x_rnn(x)[:, -1])
        shape = (-1, self.n_low, self.nk, self.nz)
        a, b = self.head_A(h).reshape(shape), self.head_b(h).reshape(shape)
        z = torch.exp(0.5 * a) * eps[:, :, None, :] + b
        return z.transpose(1, 2), a, b


def decode_k(model: MojoCVAE, x, z):
    """Returns `(b, k, t_pred, d)` for band latents `z (b, k, n_bands, nz)`; the past is encoded once."""
    b, k = z.shape[:2]
    h_x = model.encode_x(x).repeat_interleave(k, dim=0)
    ys = model.decode(x.repeat_interleave(k, dim=0), z.reshape(b * k, *z.shape[2:]), h_x)
    return ys.reshape(b, k, *ys.shape[1:])


def q_latents(q: MojoQ, x, eps, z_high):
    """Returns `(z (b, nk, n_bands, nz), a, b)`: Q's latents on the lowest L bands, `z_high (b, nk, rest, nz)` above."""
    z_low, a, b = q(x, eps)
    return torch.cat([z_low, z_high], dim=2), a, b


def sample_mojo(model: MojoCVAE, q: MojoQ, x, eps, z_high):
    """Returns MOJO's nk futures for `eps (b, L, nz)` and the N(0, I) draws `z_high` of the other bands."""
    z, _, _ = q_latents(q, x, eps, z_high)
    return decode_k(model, x, z)


def robust_kld(kld):
    return torch.sqrt(1.0 + kld**2) - 1.0


def cvae_loss(model: MojoCVAE, batch, eps, *, t_his: int, alpha: float = 3.0, beta: float = 1.0):
    """Returns `(loss, metrics)`: MOJO Eq. (1) with element means, the robust KLD Psi (the jaxmotion default)."""
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = model(x, y, eps)
    recon = torch.mean(torch.abs(y_rec - y))
    vel = torch.mean(torch.abs(torch.diff(y_rec, dim=1) - torch.diff(y, dim=1)))
    kld = torch.mean(kld_normal(mu, logvar)) / mu.shape[-1]
    loss = recon + alpha * vel + beta * robust_kld(kld)
    return loss, {"recon": recon, "vel": vel, "kld": kld}


def q_loss(q: MojoQ, model: MojoCVAE, batch, eps, z_high, *, t_his: int, d_scale: float = 100.0,
           lambda_j: float = 25.0, lambda_recon: float = 2.0, lambda_kl: float = 1.0):
    """Returns `(loss, metrics)`: DLow's objective for the per-band maps, min-of-K L1 reconstruction."""
    x, y = batch[:, :t_his], batch[:, t_his:]
    z, a, b = q_latents(q, x, eps, z_high)
    y_g = decode_k(model, x, z)
    kld = torch.mean(kld_normal(b, a))
    div = dlow_diversity(y_g, d_scale)
    recon = torch.mean(torch.amin(torch.sum(torch.abs(y_g - y[:, None]), dim=(-2, -1)), dim=1))
    loss = lambda_kl * kld + lambda_j * div + lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}
