"""DLow (Yuan & Kitani, ECCV 2020): a GRU CVAE and the Q network that maps one noise draw to K latents.

Architecture follows the paper and its released configuration for Human3.6M (`h36m_nsamp50`):
GRU encoders with 128 hidden units over X and Y, a tanh MLP (300, 200) to `mu`/`logvar`
(nz = 128), a decoder GRU initialised by an MLP of `h_x` whose input at each step is
`[h_x, z, y_{t-1}]` (y_0 = the last observed pose), then MLP (300, 200) and a linear output:
the vector-latent case of the CVAE in `models/cvae.py`, which MOJO shares.
The Q network ("NFDiag") encodes X with its own GRU and predicts K affine maps `z_k = a_k * eps + b_k`.
"""

from __future__ import annotations

import dataclasses

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.batch import batch_rows
from jaxmotion.losses import dlow_diversity, kld_affine, kld_normal, min_of_k_sq_error
from jaxmotion.models.cvae import GRUCVAE, cvae_objective, decode_k, sample_prior
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.gru import GRU
from jaxmotion.nn.linear import Dense
from jaxmotion.nn.mlp import MLP

__all__ = ["CVAEConfig", "QConfig", "DLowConfig", "DLowCVAE", "DLowQ", "decode_k", "sample_prior", "sample_dlow",
           "cvae_loss", "dlow_loss"]


@dataclasses.dataclass(slots=True)
class CVAEConfig:
    """DLow's CVAE stage (`h36m_nsamp50.yml`: nz 128, beta 0.1, lambda_v 1000, lr 1e-3, batch 64)."""

    nz: int = 128
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (300, 200)
    lr: float = 1e-3
    batch_size: int = 64
    num_steps: int = 2000
    lr_fix_fraction: float = 0.2  # DLow keeps lr constant for 100 of 500 epochs, then decays linearly to 0
    beta: float = 0.1
    lambda_v: float = 1000.0


@dataclasses.dataclass(slots=True)
class QConfig:
    """DLow's Q-network stage (`h36m_nsamp50.yml`: d_scale 100, lambda_j 25, lambda_recon 2, lr 1e-4)."""

    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (1024, 512)
    lr: float = 1e-4
    batch_size: int = 32
    num_steps: int = 1000
    lr_fix_fraction: float = 0.2
    d_scale: float = 100.0
    lambda_j: float = 25.0
    lambda_recon: float = 2.0
    lambda_kl: float = 1.0


def _synthetic_cvae() -> CVAEConfig:
    # The built-in job must finish in 10 minutes on 2 CPU cores, so it trains ~2k CVAE steps
    # where DLow trains ~39k. At that budget beta = 0.1 leaves the informative latent dimensions
    # with tiny posterior variances, and latents near the prior decode to broken bodies (on the
    # synthetic data: CVAE ADE-m 0.79 m with beta 0.1 vs 0.36 m with beta 1; DLow's Q network then
    # finds exactly those latents). beta = 1 keeps prior samples on the decoder's training distribution.
    return CVAEConfig(num_steps=2000, beta=1.0)


def _synthetic_q() -> QConfig:
    # The Q network's lr is raised from 1e-4 for the same reason (250 vs ~15k steps).
    return QConfig(num_steps=250, batch_size=16, lr=5e-4)


@dataclasses.dataclass(slots=True)
class DLowConfig:
    """DLow's settings (`Config.method_config` of method "dlow"): the CVAE stage and the Q stage (one Q network per K).

    The sections' own defaults are the paper's; the defaults here are the built-in synthetic job's budget.
    """

    cvae: CVAEConfig = dataclasses.field(default_factory=_synthetic_cvae)
    q: QConfig = dataclasses.field(default_factory=_synthetic_q)


class DLowCVAE(GRUCVAE):
    """The DLow CVAE over frame vectors `(batch, time, dim)`: a `GRUCVAE` with one `(nz,)` latent, no residual."""

    nz: int = 128
    latent: str = "vector"
    residual: bool = False


def cvae_model(c: CVAEConfig, dim: int, horizon: int, execution: Execution = Execution()) -> DLowCVAE:
    """Returns the CVAE module a `CVAEConfig` describes, run as `execution` says (nn/execution.py)."""
    return DLowCVAE(
        dim=dim, horizon=horizon, nz=c.nz, nh_rnn=c.nh_rnn, nh_mlp=tuple(c.nh_mlp), execution=execution
    )


class QTrunk(nn.Module):
    """Returns `(a, b)` each `(batch, n_heads, nk, nz)`: DLow's Q network without the affine map (GRU, MLP, heads).

    MOJO's per-band DLow uses `n_heads` = L bands (unshared heads on one trunk, the release's
    `NFDiag(freq_separate=True)`); DLow's Q network is the one-head case.
    """

    nz: int
    nk: int
    n_heads: int = 1
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (1024, 512)
    execution: Execution = Execution()  # how it runs (its products' precision): nn/execution.py

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "b t_his d"]):
        mm = self.execution.precision
        h = GRU(self.nh_rnn, mm, name="x_rnn")(x, last_only=True)
        h = MLP(self.nh_mlp, precision=mm, name="mlp")(h)
        # One Dense with n_heads * nk * nz outputs is exactly n_heads unshared linear heads.
        shape = (-1, self.n_heads, self.nk, self.nz)
        a = Dense(self.n_heads * self.nk * self.nz, precision=mm, name="head_A")(h).reshape(shape)
        b = Dense(self.n_heads * self.nk * self.nz, precision=mm, name="head_b")(h).reshape(shape)
        return a, b


class DLowQ(QTrunk):
    """DLow's Q network ("NFDiag"): returns `(z (b, nk, nz), a, b)` with `z_k = a_k * eps + b_k`."""

    nz: int = 128
    nk: int = 50

    def __call__(self, x: Float[ArrayLike, "b t_his d"], eps: Float[ArrayLike, "b z"]):
        a, b = super().__call__(x)
        a, b = a[:, 0], b[:, 0]
        return a * eps[:, None, :] + b, a, b


def q_model(c: QConfig, nz: int, nk: int, execution: Execution = Execution()) -> DLowQ:
    """Returns the Q network of a `QConfig` for `nk` samples of an `nz`-dimensional latent."""
    return DLowQ(nz=nz, nk=nk, nh_rnn=c.nh_rnn, nh_mlp=tuple(c.nh_mlp), execution=execution)


def sample_dlow(
    cvae: DLowCVAE, cvae_params, q: DLowQ, q_params, x: Float[ArrayLike, "b t_his d"], key: jax.Array
) -> Float[Array, "b nk t_pred d"]:
    """Returns DLow's `nk` futures: one noise draw per window mapped to nk latents by Q (DLow Eq. (4)).

    Args:
        cvae: the trained CVAE (frozen).
        cvae_params: its variables.
        q: the Q network; its `nk` is K, fixed when it was trained.
        q_params: its variables.
        x: observed frames `(b, t_his, D)`, metres, root-relative.
        key: a `jax.random` key; one `(b, nz)` noise draw per window.

    Returns:
        `(b, nk, t_pred, D)` futures.
    """
    eps = batch_rows(lambda n: jax.random.normal(key, (n, cvae.nz)), x.shape[0])
    z, _, _ = q.apply(q_params, x, eps)
    return decode_k(cvae, cvae_params, x, z)


def cvae_loss(cvae: DLowCVAE, params, batch: Float[ArrayLike, "b t d"], key, *, t_his: int, beta: float, lambda_v: float):
    """Returns `(loss, metrics)`: DLow's CVAE objective (`models.cvae.cvae_objective`), KL summed per window."""
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = cvae.apply(params, x, y, key)
    kld = jnp.sum(kld_normal(mu, logvar)) / batch.shape[0]
    loss, metrics = cvae_objective(y_rec, y, x[:, -1], kld, beta=beta, lambda_v=lambda_v)
    return loss, dict(metrics, kld=kld)


def dlow_loss(
    q: DLowQ, q_params, cvae: DLowCVAE, cvae_params, batch, key, *, t_his: int,
    d_scale: float, lambda_j: float, lambda_recon: float, lambda_kl: float,
):
    """Returns `(loss, metrics)`: DLow's Q objective on a frozen decoder (DLow Eq. (8)-(10)).

    loss = lambda_kl KL(N(b_k, a_k^2) || N(0,I)) + lambda_j mean_{i<j} exp(-||y_i - y_j||^2 / d_scale)
           + lambda_recon min_k ||y_k - Y||^2.
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    eps = batch_rows(lambda n: jax.random.normal(key, (n, cvae.nz)), x.shape[0])
    z, a, b = q.apply(q_params, x, eps)
    y_g = decode_k(cvae, jax.lax.stop_gradient(cvae_params), x, z)
    kld = jnp.mean(kld_affine(a, b))
    div = jnp.mean(jax.vmap(lambda yk: dlow_diversity(yk, d_scale))(y_g))
    recon = jnp.mean(jax.vmap(min_of_k_sq_error)(y_g, y))
    loss = lambda_kl * kld + lambda_j * div + lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}
