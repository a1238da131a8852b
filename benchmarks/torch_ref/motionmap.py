"""MotionMap (Hosseininejad, Shukla et al., CVPR 2025) in PyTorch: the autoencoder with its uncertainty head, the heatmap net.

The twin of the networks and losses of jaxmotion/models/motionmap.py:

* Autoencoder: GRU encoders `z_x = E_X(X)`, `z_y = E_Y(Y)` (last hidden state), the fusion MLP
  `f = tanh(Lin(tanh(Lin([z_x, z_y]))))`, a GRU-cell decoder with `h_0 = tanh(Lin(f))` fed `f` at
  every step for `t_his + t_pred` steps, frames `x_0 + Lin(h_t)`. Uncertainty head: an ELU MLP on
  the detached `f`, then a linear layer to `log sigma` per joint per frame. Loss: the per-joint
  squared error (positions times `scale`) plus the heteroscedastic NLL `e / sigma^2 + log sigma^2`
  on the detached error (MotionMap Eq. 1).
* Heatmap net: a GRU over the last `frames` observed frames, ELU then LayerNorm, a linear layer to
  the `size x size` map, ELU, `n_convs` 1 x 1 convolutions with ELU, a final 1 x 1 convolution to
  logits; weighted binary cross-entropy against Gaussian maps of the multimodal futures' cells.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from benchmarks.torch_ref.layers import GRU, MLP


class Decoder(nn.Module):
    """Returns `(b, t_total, dim)`: a GRU cell fed the fused code at every step, residual to the first frame `x0`."""

    def __init__(self, in_features: int, dim: int, t_total: int, nh: int = 128):
        super().__init__()
        self.t_total = t_total
        self.h0 = nn.Linear(in_features, nh)
        self.cell = nn.GRUCell(in_features, nh)
        self.out = nn.Linear(nh, dim)

    def forward(self, fused, x0):
        h = torch.tanh(self.h0(fused))
        hs = []
        for _ in range(self.t_total):
            h = self.cell(fused, h)
            hs.append(h)
        return x0[:, None] + self.out(torch.stack(hs, dim=1))


class MotionMapAE(nn.Module):
    """The autoencoder and uncertainty head; `forward(x, y)` returns `(frames (b, T, D), log_sigma (b, T, D // 3))`."""

    def __init__(self, dim: int, t_his: int, t_pred: int, nh_rnn: int = 128, nh_fuse: int = 256,
                 nh_uncertainty: int = 256, n_uncertainty_layers: int = 5):
        super().__init__()
        self.dim, self.t_total = dim, t_his + t_pred
        self.enc_x = GRU(dim, nh_rnn)
        self.enc_y = GRU(dim, nh_rnn)
        self.fusion = MLP(2 * nh_rnn, (nh_fuse, nh_fuse))
        self.decoder = Decoder(nh_fuse, dim, self.t_total, nh_rnn)
        self.uncertainty = MLP(nh_fuse, (nh_uncertainty,) * n_uncertainty_layers, activation="elu")
        self.uncertainty_out = nn.Linear(nh_uncertainty, self.t_total * (dim // 3))

    def encode_x(self, x):
        return self.enc_x(x)[:, -1]

    def encode_y(self, y):
        return self.enc_y(y)[:, -1]

    def decode(self, x, z_y):
        """Returns `(frames, log_sigma)` from the past X and a future code `z_y (b, nh_rnn)`."""
        fused = self.fusion(torch.cat([self.encode_x(x), z_y], dim=-1))
        frames = self.decoder(fused, x[:, 0])
        ls = self.uncertainty_out(self.uncertainty(fused.detach()))
        return frames, ls.reshape(x.shape[0], self.t_total, self.dim // 3)

    def forward(self, x, y):
        return self.decode(x, self.encode_y(y))


class HeatmapNet(nn.Module):
    """Returns `(b, size, size)` logits of the map from the last `frames` observed frames."""

    def __init__(self, dim: int, size: int, nh_rnn: int = 128, channels: int = 8, n_convs: int = 6, frames: int = 3):
        super().__init__()
        self.size, self.frames = size, frames
        self.context = GRU(dim, nh_rnn)
        self.norm = nn.LayerNorm(nh_rnn, eps=1e-6)  # flax's LayerNorm epsilon
        self.to_map = nn.Linear(nh_rnn, size * size)
        self.convs = nn.ModuleList(nn.Conv2d(1 if i == 0 else channels, channels, 1) for i in range(n_convs))
        self.final = nn.Conv2d(channels if n_convs else 1, 1, 1)

    def forward(self, x):
        h = self.norm(F.elu(self.context(x[:, -self.frames:])[:, -1]))
        m = F.elu(self.to_map(h)).reshape(-1, 1, self.size, self.size)
        for conv in self.convs:
            m = F.elu(conv(m))
        return self.final(m)[:, 0]


def reconstruction_loss(frames, log_sigma, target, scale: float):
    """Returns `(loss, metrics)`: mean per-joint squared error (x `scale`) + the uncertainty NLL on the detached error."""
    b, t, d = frames.shape
    err = torch.sum(((frames - target) * scale).reshape(b, t, d // 3, 3) ** 2, dim=-1)
    nll = err.detach() * torch.exp(-2.0 * log_sigma) + 2.0 * log_sigma
    rec = torch.mean(err)
    return rec + torch.mean(nll), {"recon": rec, "nll": torch.mean(nll), "sigma": torch.mean(torch.exp(log_sigma)) / scale}


def ae_loss(model: MotionMapAE, batch: dict, *, scale: float):
    """Returns `(loss, metrics)` of stage 1: reconstruct `[X, Y]` from X and `E_Y(Y)`."""
    frames, ls = model(batch["x"], batch["y"])
    return reconstruction_loss(frames, ls, torch.cat([batch["x"], batch["y"]], dim=1), scale)


def finetune_loss(model: MotionMapAE, table, batch: dict, *, scale: float):
    """Returns `(loss, metrics)` of stage 4: reconstruct `[X, Y]` from X and the codebook code `table[cell]`."""
    frames, ls = model.decode(batch["x"], table[batch["cell"]])
    return reconstruction_loss(frames, ls, torch.cat([batch["x"], batch["y"]], dim=1), scale)


def gaussian_heatmap(cells, mask, size: int, sigma: float):
    """Returns `(..., size, size)`: the pixel-wise max over valid cells `(..., m, 2)` of `exp(-|u - c|^2 / 2 sigma^2)`."""
    u = torch.arange(size, dtype=torch.float32)
    d2 = (u[:, None] - cells[..., 0, None, None]) ** 2 + (u[None, :] - cells[..., 1, None, None]) ** 2
    bumps = torch.where(mask[..., None, None], torch.exp(-d2 / (2 * sigma**2)), torch.zeros(()))
    return bumps.amax(dim=-3)


def heatmap_loss(model: HeatmapNet, cells, batch: dict, *, size: int, sigma: float, pos_weight: float):
    """Returns `(loss, metrics)` of stage 2: `BCEWithLogitsLoss(pos_weight)` against the Gaussian maps of `cells[members]`."""
    target = gaussian_heatmap(cells[batch["members"]].float(), batch["mask"], size, sigma)
    logits = model(batch["x"])
    loss = F.binary_cross_entropy_with_logits(logits, target, pos_weight=torch.tensor(pos_weight))
    return loss, {"bce": loss, "peak_prob": torch.mean(torch.sigmoid(logits).amax(dim=(1, 2)))}
