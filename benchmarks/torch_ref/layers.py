"""Building blocks shared by the PyTorch reference models: DLow's tanh MLP and a batch-first GRU."""

from __future__ import annotations

import torch
from torch import nn


class MLP(nn.Module):
    """Returns `tanh(Linear(...tanh(Linear(x))))`: jaxmotion.nn.mlp.MLP (a nonlinearity after every layer)."""

    def __init__(self, in_features: int, features: tuple[int, ...], activation: str = "tanh"):
        super().__init__()
        dims = (in_features,) + tuple(features)
        self.layers = nn.ModuleList(nn.Linear(i, o) for i, o in zip(dims[:-1], dims[1:]))
        self.act = torch.tanh if activation == "tanh" else getattr(torch.nn.functional, activation)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers:
            x = self.act(layer(x))
        return x


class GRU(nn.Module):
    """Returns all hidden states `(batch, time, hidden)`: jaxmotion.nn.gru.GRU as one fused `nn.GRU` layer.

    `nn.GRU` runs the whole sequence in one ATen kernel, the fastest eager PyTorch has; its gates
    (r, z, n) and biases are exactly jaxmotion's GRUCell's.
    """

    def __init__(self, in_features: int, features: int):
        super().__init__()
        self.rnn = nn.GRU(in_features, features, batch_first=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.rnn(x)[0]
