"""DivSamp (Dang et al., ACM MM 2022) in PyTorch: the GCN CVAE on DCT coefficients and the Gumbel sampler.

The twin of jaxmotion/models/divsamp.py and jaxmotion/nn/gcn.py (graph convolutions with a learnable
adjacency, GCL-BN-Tanh layers normalising each of the J * F features). The sampler takes its
random draws as tensors (the coefficient matrix W and the noise eps) so both frameworks can be fed
the same ones; `gumbel_coefficients` draws W here for the benchmark.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from benchmarks.torch_ref.dct import dct, idct
from benchmarks.torch_ref.dlow import kld_normal


class GraphConv(nn.Module):
    """Returns `A H W + b` for node features `H (..., J, F_in)`."""

    def __init__(self, n_nodes: int, in_features: int, features: int):
        super().__init__()
        bound = 1.0 / math.sqrt(features)
        self.weight = nn.Parameter(torch.empty(in_features, features).uniform_(-bound, bound))
        self.att = nn.Parameter(torch.empty(n_nodes, n_nodes).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(features).uniform_(-bound, bound))

    def forward(self, h):
        return self.att @ (h @ self.weight) + self.bias


class GCLBlock(nn.Module):
    """Returns `tanh(BN(GraphConv(H)))`, BatchNorm1d over the J * F outputs (statistics over all leading axes)."""

    def __init__(self, n_nodes: int, in_features: int, features: int):
        super().__init__()
        self.gc = GraphConv(n_nodes, in_features, features)
        self.bn = nn.BatchNorm1d(n_nodes * features, eps=1e-5, momentum=0.1)

    def forward(self, h):
        x = self.gc(h)
        shape = x.shape
        return torch.tanh(self.bn(x.reshape(-1, shape[-2] * shape[-1])).reshape(shape))


class ResidualGCLBlock(nn.Module):
    def __init__(self, n_nodes: int, features: int):
        super().__init__()
        self.gcl_0 = GCLBlock(n_nodes, features, features)
        self.gcl_1 = GCLBlock(n_nodes, features, features)

    def forward(self, h):
        return self.gcl_1(self.gcl_0(h)) + h


class GCLStack(nn.Module):
    """Returns `(..., J, features)` after `1 + 2 * num_residual` GCL-BN-Tanh layers."""

    def __init__(self, n_nodes: int, in_features: int, features: int, num_residual: int):
        super().__init__()
        self.gcl_in = GCLBlock(n_nodes, in_features, features)
        self.res = nn.ModuleList(ResidualGCLBlock(n_nodes, features) for _ in range(num_residual))

    def forward(self, h):
        h = self.gcl_in(h)
        for block in self.res:
            h = block(h)
        return h


def pad_history(x, t_pred: int):
    return torch.cat([x, x[:, -1:].expand(-1, t_pred, -1)], dim=1)


def to_nodes(seq, n_dct: int):
    """Returns `(b, J, 3 n_dct)`: per joint [x_0..x_{n-1}, y_0.., z_0..] DCT coefficients."""
    c = dct(seq, n_dct)
    b, n, d = c.shape
    return c.reshape(b, n, d // 3, 3).permute(0, 2, 3, 1).reshape(b, d // 3, 3 * n)


def from_nodes(nodes, n_frames: int):
    b, j, c = nodes.shape
    n = c // 3
    return idct(nodes.reshape(b, j, 3, n).permute(0, 3, 1, 2).reshape(b, n, j * 3), n_frames)


def condition_nodes(x, t_pred: int, n_dct: int):
    return to_nodes(pad_history(x, t_pred), n_dct)


def bone_lengths(frames, parents):
    pos = frames.reshape(*frames.shape[:-1], -1, 3)
    pos = torch.cat([torch.zeros_like(pos[..., :1, :]), pos], dim=-2)
    child = list(range(1, len(parents)))
    return torch.linalg.norm(pos[..., child, :] - pos[..., [parents[c] for c in child], :], dim=-1)


class DivSampCVAE(nn.Module):
    """DivSamp's GCN CVAE; `forward(cx, cw, eps)` returns `(nodes_rec, mu, logvar)`."""

    def __init__(self, n_nodes: int, n_dct: int = 10, hidden: int = 256, nz: int = 64, num_residual: int = 4):
        super().__init__()
        self.n_dct, self.nz = n_dct, nz
        c = 3 * n_dct
        self.enc = GCLStack(n_nodes, 2 * c, hidden, num_residual)
        self.e_mu = nn.Linear(n_nodes * hidden, nz)
        self.e_logvar = nn.Linear(n_nodes * hidden, nz)
        self.dec = GCLStack(n_nodes, c + nz, hidden, num_residual)
        self.d_out = GraphConv(n_nodes, hidden, c)

    def encode(self, cx, cw):
        h = self.enc(torch.cat([cx, cw], dim=-1)).flatten(1)
        return self.e_mu(h), self.e_logvar(h)

    def decode(self, cx, z):
        zj = z[:, None, :].expand(-1, cx.shape[1], -1)
        return self.d_out(self.dec(torch.cat([cx, zj], dim=-1))) + cx

    def forward(self, cx, cw, eps=None):
        mu, logvar = self.encode(cx, cw)
        z = mu if eps is None else mu + torch.exp(0.5 * logvar) * eps
        return self.decode(cx, z), mu, logvar


class GammaHead(nn.Module):
    def __init__(self, in_features: int, nh: int, out: int):
        super().__init__()
        self.dense_0 = nn.Linear(in_features, nh)
        self.bn = nn.BatchNorm1d(nh, eps=1e-5, momentum=0.1)
        self.dense_1 = nn.Linear(nh, out)

    def forward(self, p):
        h = self.dense_0(p)
        h = self.bn(h.reshape(-1, h.shape[-1])).reshape(h.shape)
        return self.dense_1(torch.tanh(h))


class DivSampSampler(nn.Module):
    """DivSamp's sampler; `forward(cx, w, eps)` returns `(z (b, K, nz), mean, logvar)` for coefficients `w (b, K, M)`."""

    def __init__(self, n_nodes: int, n_dct: int = 10, nz: int = 64, hidden: int = 256, num_residual: int = 2,
                 num_bases: int = 40, base_dim: int = 128, nh: int = 64, base_tanh: bool = True):
        super().__init__()
        self.num_bases, self.base_dim, self.base_tanh, self.nz = num_bases, base_dim, base_tanh, nz
        self.condition_enc = GCLStack(n_nodes, 3 * n_dct, hidden, num_residual)
        self.bases = nn.Linear(n_nodes * hidden, num_bases * base_dim)
        self.bases_bn = nn.BatchNorm1d(num_bases * base_dim, eps=1e-5, momentum=0.1)
        self.mean = GammaHead(base_dim, nh, nz)
        self.logvar = GammaHead(base_dim, nh, nz)

    def forward(self, cx, w, eps):
        """`w (b, K, M)`: rows on the simplex; `eps (b, 1, nz)`: one draw per window (DivSamp Eq. (11)-(12))."""
        base = self.bases_bn(self.bases(self.condition_enc(cx).flatten(1)))
        if self.base_tanh:
            base = torch.tanh(base)
        p = w @ base.reshape(-1, self.num_bases, self.base_dim)
        mean, logvar = self.mean(p), self.logvar(p)
        return torch.exp(0.5 * logvar) * eps + mean, mean, logvar


def gumbel_coefficients(b: int, k: int, m: int, tau: float = 1.0, generator=None):
    """Returns W (b, k, m) with Gumbel-Softmax rows for a uniform pi (DivSamp Eq. (9)-(10))."""
    u = torch.rand(b, k, m, generator=generator).clamp_min(torch.finfo(torch.float32).tiny)
    return torch.softmax(-torch.log(-torch.log(u)) / tau, dim=-1)


def decode_k(cvae: DivSampCVAE, cx, z, *, t_his: int, t_pred: int):
    """Returns `(b, K, t_pred, D)` for latents `z (b, K, nz)`; the K decodes run as one batch of b * K."""
    b, k = z.shape[:2]
    nodes = cvae.decode(cx.repeat_interleave(k, dim=0), z.reshape(b * k, -1))
    return from_nodes(nodes, t_his + t_pred)[:, t_his:].reshape(b, k, t_pred, -1)


def sample_divsamp(cvae: DivSampCVAE, sampler: DivSampSampler, x, w, eps, *, t_pred: int):
    """Returns DivSamp's K futures (Alg. 2) for coefficients `w (b, K, M)` and noise `eps (b, 1, nz)`."""
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    z, _, _ = sampler(cx, w, eps)
    return decode_k(cvae, cx, z, t_his=x.shape[1], t_pred=t_pred)


def cvae_loss(cvae: DivSampCVAE, batch, eps, *, t_his: int, parents, beta: float = 0.5, lambda_v: float = 1000.0,
              lambda_his: float = 1.0, lambda_limb: float = 1000.0):
    """Returns `(loss, metrics)`: jaxmotion.models.divsamp.cvae_loss with the noise `eps (b, nz)` given."""
    t_pred = batch.shape[1] - t_his
    x, y = batch[:, :t_his], batch[:, t_his:]
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    cw = to_nodes(batch, cvae.n_dct)
    nodes, mu, logvar = cvae(cx, cw, eps)
    rec = from_nodes(nodes, batch.shape[1])
    b = batch.shape[0]
    recon = torch.sum((rec[:, t_his:] - y) ** 2) / b
    jump = torch.sum((x[:, -1] - rec[:, t_his]) ** 2) / b
    kld = torch.sum(kld_normal(mu, logvar)) / b
    his = torch.mean(torch.sum((rec[:, :t_his] - x) ** 2, dim=-1))
    limb = torch.mean(torch.sum((bone_lengths(rec, parents) - bone_lengths(batch[:, :1], parents)) ** 2, dim=-1))
    loss = recon + lambda_v * jump + beta * kld + lambda_his * his + lambda_limb * limb
    return loss, {"recon": recon, "jump": jump, "kld": kld, "his": his, "limb": limb}


def hinge_diversity(y, eta: float):
    """Returns the mean over windows of mean_{i<j} max(0, eta - ||y_i - y_j||) for `y (b, k, ...)` (Eq. (13))."""
    b, k = y.shape[:2]
    y = y.reshape(b, k, -1)
    sq = torch.sum(y**2, dim=-1)
    d2 = torch.clamp(sq[:, :, None] + sq[:, None, :] - 2.0 * y @ y.transpose(1, 2), min=0.0)
    iu = torch.triu_indices(k, k, 1)
    d = torch.sqrt(torch.clamp(d2[:, iu[0], iu[1]], min=1e-12))
    return torch.mean(torch.clamp(eta - d, min=0.0))


def sampler_loss(sampler: DivSampSampler, cvae: DivSampCVAE, batch, w, eps, *, t_his: int, lambda_kl: float = 0.5,
                 lambda_acc: float = 40.0, lambda_div: float = 20.0, eta: float = 25.0):
    """Returns `(loss, metrics)`: DivSamp Eq. (13)-(15) on the decoder `cvae` (put it in eval mode)."""
    t_pred = batch.shape[1] - t_his
    x, y = batch[:, :t_his], batch[:, t_his:]
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    z, mean, logvar = sampler(cx, w, eps)
    y_k = decode_k(cvae, cx, z, t_his=t_his, t_pred=t_pred)
    kld = torch.mean(kld_normal(mean, logvar))
    acc = torch.mean(torch.amin(torch.sum((y_k - y[:, None]) ** 2, dim=(-2, -1)), dim=-1))
    div = hinge_diversity(y_k, eta)
    loss = lambda_div * div + lambda_acc * acc + lambda_kl * kld
    return loss, {"div": div, "recon": acc, "kld": kld}
