"""An action classifier over future motion, whose penultimate layer gives the project's FID features ([protocol §3][realism-and-action-metrics]).

    h_t = GRU(h_{t-1}, y_t)   (h_0 = 0),    f = tanh(W_1 h_T + b_1),    logits = W_2 f + b_2

over a future `y` of shape `(t_pred, D)` (frame vectors, [protocol §1][representation]). `f` (`features`
numbers, 30 by default) is what FID compares. The layout follows BeLFusion's `ClassifierForFID`
(`models/fid_classifier.py`: GRU, last hidden state, Linear(30) + tanh, Linear(classes)), with
three differences: the initial hidden state is zero (BeLFusion draws `torch.randn` at every call,
so its features of one motion differ between calls), the GRU is one layer of 32 by default
(BeLFusion: two of 128; evaluation runs it over all K x N predicted futures, and on Bandai-Namco-2
32 units gave a higher test accuracy than 64, 0.89 against 0.85 after 2000 steps), and it is trained
by this project on its own datasets' labels (`jaxmotion.train.action_classifier.train`, called by
`jaxmotion.eval.action_metrics.dataset_classifier`).

This is NOT BeLFusion's Human3.6M classifier (`auxiliar/h36m_classifier.pth`): FID values computed
with it compare only with other FID values of this project on the same dataset.
"""

from __future__ import annotations

import dataclasses

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from jaxmotion.nn.gru import GRU


@dataclasses.dataclass(frozen=True)
class ClassifierConfig:
    """The classifier's size and its training budget (every field is part of the cache key)."""

    hidden: int = 32  # GRU width
    layers: int = 1  # stacked GRU layers
    features: int = 30  # width of the feature layer (BeLFusion: 30)
    num_steps: int = 1000
    batch_size: int = 64
    lr: float = 2e-3  # Adam, cosine decay to 5% over num_steps
    seed: int = 0  # initialisation and batch draws: fixed, so a dataset has one classifier

    def __post_init__(self):
        for name in ("hidden", "layers", "features", "num_steps", "batch_size"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"ClassifierConfig.{name} must be an integer >= 1, got {v!r}")
        if not self.lr > 0:
            raise ValueError(f"ClassifierConfig.lr must be > 0, got {self.lr!r}")


class ActionClassifier(nn.Module):
    """Returns `(logits (b, classes), features (b, features))` of futures `(b, t, D)` (module docstring)."""

    num_classes: int
    hidden: int = 32
    layers: int = 1
    features: int = 30
    unroll: int = 1  # the GRU loop's `lax.scan` unroll (`predict` runs it fully unrolled; same parameters)

    @nn.compact
    def __call__(self, y: Float[ArrayLike, "b t d"]) -> tuple[Float[Array, "b c"], Float[Array, "b f"]]:
        h = jnp.asarray(y, jnp.float32)
        for i in range(self.layers):
            h = GRU(self.hidden, unroll=self.unroll, name=f"gru{i}")(h)  # zero initial state: deterministic features
        f = jnp.tanh(nn.Dense(self.features, name="feature")(h[:, -1]))
        return nn.Dense(self.num_classes, name="logits")(f), f


def make_model(num_classes: int, c: ClassifierConfig) -> ActionClassifier:
    """Returns the classifier of `c`'s size for `num_classes` classes."""
    return ActionClassifier(num_classes, hidden=c.hidden, layers=c.layers, features=c.features)


# One jitted function for every classifier: a module is hashable by its fields, so evaluations of
# several runs in one process share the compiled code of each (module, batch shape).
_apply = jax.jit(lambda model, params, y: model.apply(params, y), static_argnums=0)


def predict(
    model: ActionClassifier, params, y: Float[ArrayLike, "n t d"], batch: int = 256
) -> tuple[Float[np.ndarray, "n c"], Float[np.ndarray, "n f"]]:
    """Returns `(logits, features)` of futures `y`, run in padded batches of `batch` rows (one compile per size).

    The GRU loop runs fully unrolled: evaluation's batches of K x 64 futures of a 32-unit GRU spend
    most of a rolled loop's time between steps; unrolled, XLA fuses across steps (2.6x faster at
    3,200 futures of 60 frames on the 2-core Xeon; the backward pass, in training, gains nothing).
    """
    y = np.asarray(y, np.float32)
    model = model.clone(unroll=max(model.unroll, y.shape[1]))
    n, out = y.shape[0], []
    for s in range(0, n, batch):
        yb = y[s : s + batch]
        c = yb.shape[0]
        if c < batch:
            yb = np.concatenate([yb, np.repeat(yb[-1:], batch - c, axis=0)])
        out.append(tuple(np.asarray(a)[:c] for a in _apply(model, params, jnp.asarray(yb))))
    logits, feats = (np.concatenate(parts) for parts in zip(*out))
    return logits, feats


def accuracy(
    model: ActionClassifier, params, y: Float[ArrayLike, "n t d"], labels: Int[ArrayLike, " n"], batch: int = 256
) -> float:
    """Returns the fraction of futures `y` whose most likely class is `labels`."""
    logits, _ = predict(model, params, y, batch)
    return float(np.mean(np.argmax(logits, -1) == np.asarray(labels)))
