"""MOJO (Zhang, Black & Tang, CVPR 2021, "We are More than Our Joints"): a CVAE with a latent DCT space.

The CVAE is `models.cvae.GRUCVAE` (DLow's CVAE is its one-band case) with MOJO's defaults.
Matched against the authors' release (`yz-cnsdqz/MOJO-release`: `models/models_mojo.py` class
`VAEDCT` and `NFDiag(freq_separate=True)`, `experiments/train_MOJO_vae.py`,
`experiments/train_MOJO_dlow.py`, config `amass_mojo_f9_nsamp50.yml`):

- Encoder (paper Sec. 3.3, Fig. 2/S2): a GRU over X gives `h_x` (its last state); a GRU over Y keeps
  one hidden state per future frame; `[h_x, h_y,t]` is DCT-transformed over the `t_pred` frames, and
  the same MLP + two linear layers map *each frequency band* to a mean and log-variance of
  `nz` (= 16) numbers. So the latent is `(t_pred bands, nz)`.
- Sampling `z` by reparameterisation, inverse DCT back to time: `z_t` per future frame.
- Decoder: a GRU cell started from `MLP(h_x)` whose input at step t is `[h_x, z_t, y_{t-1}]`
  (`y_0` = the last observed frame), then MLP (300, 200) and a linear layer predicting the change
  from the previous frame (residual output, `residual: true`).
- Loss (Eq. (1)): `|Y - Yrec|_1 + alpha |dY - dYrec|_1 + Psi(KLD)`, alpha = 3 (`lambda_tf`),
  `Psi(s) = sqrt(1+s^2) - 1`; as in the release every term is a mean over its elements
  (`F.l1_loss`, `0.5 * torch.mean(...)` for the KLD), weight 1, no annealing.
- Sampler: one DLow affine map per low band (`n_freq` = 9 of 45 bands, the lowest 20%), heads
  unshared, trunk (GRU + MLP) shared as in the release's `NFDiag(freq_separate=True)`
  (`MojoConfig.q_shared_trunk=False` gives a full DLow network per band); `z_k = exp(a_k / 2) eps +
  b_k` with `a` a log-variance; the bands above the lowest L are drawn from N(0, I) independently
  per sample; losses of DLow (KL of the affine maps, diversity `exp(-d^2/d_scale)`, min-of-K
  reconstruction, the release's L1 norm for MOJO) on the frozen decoder.

Variants from the same code (`MojoConfig.latent`, `.loss`, `.residual`): MOJO-DCT (one 128-d latent
vector, KLD weight 0.1 = the release's `amass_vanilla` model), VAE+DCT (DLow's CVAE objective with
the latent DCT space, no residual), VAE+DCT+L (that CVAE with DLow on the lowest L bands).

The decoder step is public (`decode_step(params, carry, inputs) -> (carry, frame)`) so recursive
projection can run it inside its own `lax.scan` and replace each predicted frame before the next
step.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.nn.batch import batch_rows
from jaxmotion.losses import dlow_diversity, kld_normal, min_of_k_sq_error, robust_kld
from jaxmotion.models.cvae import DecodeCarry, DecodeInputs, GRUCVAE, cvae_objective, decode_k, sample_prior
from jaxmotion.models.dlow import QTrunk
from jaxmotion.nn.execution import Execution

__all__ = ["MojoConfig", "MojoCVAE", "MojoQ", "DecodeCarry", "DecodeInputs", "decode_k", "sample_prior", "q_latents",
           "sample_mojo", "cvae_loss", "q_loss", "decoder_params", "decode_inputs", "decode_step", "latent_spectrum"]


@dataclasses.dataclass(slots=True)
class MojoConfig:
    """MOJO's settings (defaults: the paper / `amass_mojo_f9_nsamp50.yml`, GRU width as DLow here)."""

    variant: str = "MOJO"  # a label for tables: MOJO, MOJO-DCT, VAE+DCT, ...
    latent: str = "dct"  # "dct": nz numbers per DCT band of the t_pred frames; "vector": one nz vector
    nz: int = 16
    nh_rnn: int = 128  # the release defaults to 256; 128 matches this project's DLow for a fair budget
    nh_mlp: tuple[int, ...] = (300, 200)
    residual: bool = True  # decoder predicts the change from the previous frame
    # "mojo": Eq. (1), L1 + alpha * velocity L1 + beta * Psi(KLD) (or plain KLD), element means.
    # "dlow": DLow's CVAE objective, squared error + lambda_v * jump + beta * KLD, sums / batch.
    loss: str = "mojo"
    alpha: float = 3.0
    beta: float = 1.0
    robust_kld: bool = True
    lambda_v: float = 1000.0  # "dlow" loss only
    lr: float = 1e-3
    batch_size: int = 64
    num_steps: int = 2000
    lr_fix_fraction: float = 0.2
    # Second stage: DLow on the lowest L bands, N(0, I) above.
    dlow_band_fraction: float = 0.2
    q_shared_trunk: bool = True
    q_nh_rnn: int = 128
    q_nh_mlp: tuple[int, ...] = (1024, 512)
    q_lr: float = 1e-4
    q_batch_size: int = 16
    q_num_steps: int = 400  # 0: no Q stage (the CVAE alone, e.g. MOJO's VAE+DCT row)
    q_lr_fix_fraction: float = 0.2
    d_scale: float = 100.0
    lambda_j: float = 25.0
    lambda_recon: float = 2.0
    lambda_kl: float = 1.0
    # The second stage's best-of-K reconstruction term: "l1", min_k sum |y_k - Y| (MOJO's release,
    # `train_MOJO_dlow.py`); "sq", min_k sum (y_k - Y)^2 (DLow's release); None: "l1" with MOJO's CVAE
    # objective, "sq" with DLow's.
    q_recon: str | None = None
    # Extra samplers evaluated beside the config's own ("mojo"): "zero_velocity", "mojo_prior", and
    # "mojo_proj" (MOJO with recursive projection; marker datasets with a body, `info["body"]`).
    baselines: tuple[str, ...] = ("zero_velocity", "mojo_prior")
    # Recursive projection: Levenberg-Marquardt steps per fitting stage (global, then body) per frame.
    proj_max_steps: int = 10

    def __post_init__(self):
        if self.latent not in ("dct", "vector"):
            raise ValueError(f"MojoConfig.latent must be 'dct' or 'vector', got {self.latent!r}")
        if self.loss not in ("mojo", "dlow"):
            raise ValueError(f"MojoConfig.loss must be 'mojo' or 'dlow', got {self.loss!r}")
        if self.q_recon not in (None, "l1", "sq"):
            raise ValueError(f"MojoConfig.q_recon must be 'l1', 'sq' or None (follows loss), got {self.q_recon!r}")
        if not 0.0 < self.dlow_band_fraction <= 1.0:
            raise ValueError(f"MojoConfig.dlow_band_fraction must be in (0, 1], got {self.dlow_band_fraction}")
        unknown = set(self.baselines) - {"zero_velocity", "mojo_prior", "mojo_proj"}
        if unknown:
            raise ValueError(
                f"MojoConfig.baselines: unknown {sorted(unknown)}; known: zero_velocity, mojo_prior, mojo_proj"
            )
        if self.q_num_steps < 0:
            raise ValueError(f"MojoConfig.q_num_steps must be >= 0 (0: the CVAE alone), got {self.q_num_steps}")
        if self.q_num_steps == 0 and "mojo_prior" not in self.baselines:
            raise ValueError("MojoConfig.q_num_steps = 0 trains no Q network: add 'mojo_prior' to baselines to sample the CVAE")
        if self.proj_max_steps < 1:
            raise ValueError(f"MojoConfig.proj_max_steps must be >= 1, got {self.proj_max_steps}")


def num_bands(latent: str, horizon: int) -> int:
    """Returns the number of latent bands: one per future frame for the DCT latent, else 1."""
    return horizon if latent == "dct" else 1


def num_low_bands(cfg: MojoConfig, horizon: int) -> int:
    """Returns L, the number of lowest bands sampled by DLow (at least 1; release: 9 of 45)."""
    return max(1, round(cfg.dlow_band_fraction * num_bands(cfg.latent, horizon)))


class MojoCVAE(GRUCVAE):
    """MOJO's CVAE over frame vectors `(batch, time, dim)`: a `GRUCVAE` with a DCT latent and a residual decoder.

    `mu`, `logvar` are `(batch, horizon, nz)`, one Gaussian per DCT band ("dct"), or `(batch, nz)` ("vector", MOJO-DCT).
    """

    nz: int = 16
    latent: str = "dct"
    residual: bool = True


def cvae_model(cfg: MojoConfig, dim: int, horizon: int, execution: Execution = Execution()) -> MojoCVAE:
    """Returns the CVAE module a `MojoConfig` describes, run as `execution` says (nn/execution.py)."""
    return MojoCVAE(
        dim=dim, horizon=horizon, nz=cfg.nz, nh_rnn=cfg.nh_rnn, nh_mlp=tuple(cfg.nh_mlp),
        latent=cfg.latent, residual=cfg.residual, execution=execution,
    )


# --------------------------------------------------------------------------------------------
# The public decoder step (for recursive projection).


class DecoderParams(struct.PyTreeNode):
    """A trained decoder: the CVAE's `variables` (a pytree) and its module (static, hashable)."""

    variables: Any
    model: MojoCVAE = struct.field(pytree_node=False)


def decoder_params(model: MojoCVAE, variables) -> DecoderParams:
    """Returns the `params` argument of `decode_step` / `decode_inputs` for a trained CVAE."""
    return DecoderParams(variables, model)


def decode_inputs(params: DecoderParams, x: Float[ArrayLike, "b t_his d"], z: Float[ArrayLike, "b *bands z"]):
    """Returns `(carry0, inputs)` for `lax.scan(lambda c, i: decode_step(params, c, i), carry0, inputs)`.

    `inputs` are time-major `DecodeInputs` with leading axis `t_pred`; `z` holds the band latents.
    """
    return params.model.apply(params.variables, x, z, method=MojoCVAE.decode_init)


def decode_step(params: DecoderParams, carry: DecodeCarry, inputs: DecodeInputs) -> tuple[DecodeCarry, Float[Array, "b d"]]:
    """Returns `(carry', frame (b, D))`: one step of MOJO's decoder (a pure function, `lax.scan`-able).

    To project the prediction onto a valid body, replace `carry'.y_prev` by the fitted frame
    before the next step (`carry._replace(y_prev=fitted)`): the next step then starts from it.
    """
    return params.model.apply(params.variables, carry, inputs, method=MojoCVAE.decode_step)


# --------------------------------------------------------------------------------------------
# The second stage: DLow on the lowest L bands.


class MojoQ(nn.Module):
    """Per-band DLow: returns `(z (b, nk, L, nz), a, b)` with `z_k = exp(a_k / 2) * eps + b_k` per band.

    `eps (b, L, nz)` is one noise draw per window and band, shared by the nk maps (DLow Eq. (4));
    `a` is a log-variance as in the release's `NFDiag`. With `shared_trunk` the L bands share the
    GRU + MLP and have their own heads (the release); otherwise every band has a whole network.
    """

    nz: int
    nk: int
    n_low: int
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (1024, 512)
    shared_trunk: bool = True
    execution: Execution = Execution()  # as QTrunk.execution

    @nn.compact
    def __call__(self, x: Float[ArrayLike, "b t_his d"], eps: Float[ArrayLike, "b l z"]):
        if self.shared_trunk:
            a, b = QTrunk(self.nz, self.nk, self.n_low, self.nh_rnn, tuple(self.nh_mlp), self.execution, name="q")(x)
        else:
            bands = nn.vmap(
                QTrunk, variable_axes={"params": 0}, split_rngs={"params": True},
                in_axes=None, out_axes=1, axis_size=self.n_low,
            )
            a, b = bands(self.nz, self.nk, 1, self.nh_rnn, tuple(self.nh_mlp), self.execution, name="q")(x)
            a, b = a[:, :, 0], b[:, :, 0]
        z = jnp.exp(0.5 * a) * eps[:, :, None, :] + b  # (b, L, nk, nz)
        return jnp.swapaxes(z, 1, 2), a, b


def q_model(cfg: MojoConfig, horizon: int, nk: int, execution: Execution = Execution()) -> MojoQ:
    """Returns the per-band DLow module of a `MojoConfig` for `nk` samples."""
    return MojoQ(
        nz=cfg.nz, nk=nk, n_low=num_low_bands(cfg, horizon), nh_rnn=cfg.q_nh_rnn,
        nh_mlp=tuple(cfg.q_nh_mlp), shared_trunk=cfg.q_shared_trunk, execution=execution,
    )


# --------------------------------------------------------------------------------------------
# Samplers.


def q_latents(model: MojoCVAE, q: MojoQ, q_params, x, key: jax.Array):
    """Returns `(z (b, nk) + latent_shape, a, b)`: DLow latents on the lowest L bands, N(0, I) above."""
    k_eps, k_high = jax.random.split(key)
    eps = batch_rows(lambda n: jax.random.normal(k_eps, (n, q.n_low, model.nz)), x.shape[0])
    z_low, a, b = q.apply(q_params, x, eps)
    z_high = batch_rows(lambda n: jax.random.normal(k_high, (n, q.nk, model.n_bands - q.n_low, model.nz)), x.shape[0])
    z = jnp.concatenate([z_low, z_high], axis=2)
    return z.reshape(z.shape[:2] + model.latent_shape), a, b


def sample_mojo(
    model: MojoCVAE, params, q: MojoQ, q_params, x: Float[ArrayLike, "b t_his d"], key: jax.Array
) -> Float[Array, "b nk t_pred d"]:
    """Returns MOJO's nk futures: per-band DLow on the lowest L bands, N(0, I) on the rest (MOJO Sec. 3.3).

    Args:
        model: the trained latent-DCT CVAE (frozen).
        params: its variables.
        q: the per-band Q network (`nk` futures, `n_low` bands).
        q_params: its variables.
        x: observed frames `(b, t_his, D)` (joints, or markers in the canonical frame).
        key: a `jax.random` key.

    Returns:
        `(b, nk, t_pred, D)` futures.
    """
    z, _, _ = q_latents(model, q, q_params, x, key)
    return decode_k(model, params, x, z)


# --------------------------------------------------------------------------------------------
# Objectives: each takes its own weights, as keywords.


def cvae_loss(
    model: MojoCVAE, params, batch: Float[ArrayLike, "b t d"], key, *, t_his: int, objective: str = "mojo",
    alpha: float = 3.0, beta: float = 1.0, robust: bool = True, lambda_v: float = 1000.0,
):
    """Returns `(loss, metrics)`: MOJO Eq. (1) (`objective="mojo"`) or DLow's CVAE objective (`"dlow"`).

    "mojo": mean|Y - Yrec| + alpha mean|dY - dYrec| + beta Psi(KLD), KLD = 0.5 mean(-1 - logvar +
    mu^2 + exp(logvar)) over batch, bands and dims (the release's element means); Psi only if
    `robust`. "dlow": `models.cvae.cvae_objective` (squared error + lambda_v jump, sums / batch)
    with beta Psi(KLD) when `robust`, else beta KLD.
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = model.apply(params, x, y, key)
    if objective == "mojo":
        recon = jnp.mean(jnp.abs(y_rec - y))
        vel = jnp.mean(jnp.abs(jnp.diff(y_rec, axis=1) - jnp.diff(y, axis=1)))
        kld = jnp.mean(kld_normal(mu, logvar)) / mu.shape[-1]
        kl_term = robust_kld(kld) if robust else kld
        loss = recon + alpha * vel + beta * kl_term
        return loss, {"recon": recon, "vel": vel, "kld": kld}
    if objective != "dlow":
        raise ValueError(f"mojo.cvae_loss: objective must be 'mojo' or 'dlow', got {objective!r}")
    kld = jnp.sum(kld_normal(mu, logvar)) / batch.shape[0]
    kl_term = robust_kld(kld) if robust else kld
    loss, metrics = cvae_objective(y_rec, y, x[:, -1], kl_term, beta=beta, lambda_v=lambda_v)
    return loss, dict(metrics, kld=kld)


def cvae_loss_weights(cfg: MojoConfig) -> dict:
    """Returns the keyword weights of `cvae_loss` that a `MojoConfig` sets."""
    return dict(objective=cfg.loss, alpha=cfg.alpha, beta=cfg.beta, robust=cfg.robust_kld, lambda_v=cfg.lambda_v)


def min_of_k_l1_error(y_k: Float[ArrayLike, "k t d"], y: Float[ArrayLike, "t d"]) -> Float[Array, ""]:
    """Returns min_k sum_{t,d} |y_k - y|: the release's MOJO reconstruction term for one window."""
    return jnp.min(jnp.sum(jnp.abs(y_k - y[None]), axis=(-2, -1)))


def q_loss(
    q: MojoQ, q_params, model: MojoCVAE, cvae_params, batch, key, *, t_his: int, recon_norm: str = "l1",
    d_scale: float = 100.0, lambda_j: float = 25.0, lambda_recon: float = 2.0, lambda_kl: float = 1.0,
):
    """Returns `(loss, metrics)`: DLow's objective (DLow Eq. (8)-(10)) for the per-band maps on a frozen decoder.

    loss = lambda_kl mean_{b,k,band} KL(N(b, exp(a)) || N(0,I)) + lambda_j mean_{i<j} exp(-||y_i - y_j||^2 / d_scale)
           + lambda_recon min_k ||y_k - Y|| (`recon_norm` "l1" for MOJO's loss as in the release, "sq" for DLow's).
    """
    if recon_norm not in ("l1", "sq"):
        raise ValueError(f"mojo.q_loss: recon_norm must be 'l1' or 'sq', got {recon_norm!r}")
    x, y = batch[:, :t_his], batch[:, t_his:]
    z, a, b = q_latents(model, q, q_params, x, key)
    y_g = decode_k(model, jax.lax.stop_gradient(cvae_params), x, z)
    kld = jnp.mean(kld_normal(b, a))
    div = jnp.mean(jax.vmap(lambda yk: dlow_diversity(yk, d_scale))(y_g))
    recon_fn = min_of_k_l1_error if recon_norm == "l1" else min_of_k_sq_error
    recon = jnp.mean(jax.vmap(recon_fn)(y_g, y))
    loss = lambda_kl * kld + lambda_j * div + lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}


def q_loss_weights(cfg: MojoConfig) -> dict:
    """Returns the keyword weights of `q_loss` that a `MojoConfig` sets (the reconstruction norm: `cfg.q_recon`, or
    the one of `cfg.loss`'s release where it is None)."""
    recon = cfg.q_recon or ("l1" if cfg.loss == "mojo" else "sq")
    return dict(
        recon_norm=recon, d_scale=cfg.d_scale, lambda_j=cfg.lambda_j,
        lambda_recon=cfg.lambda_recon, lambda_kl=cfg.lambda_kl,
    )


def latent_spectrum(model: MojoCVAE, params, x, y) -> tuple[Float[Array, " c"], Float[Array, " c"]]:
    """Returns per-band `(mean |mu|, mean |logvar|)` over windows and latent dims (MOJO Fig. S5)."""
    mu, logvar = model.apply(params, x, y, method=MojoCVAE.encode)
    mu, logvar = (a.reshape(a.shape[0], -1, a.shape[-1]) for a in (mu, logvar))  # a vector latent is one band
    return jnp.mean(jnp.abs(mu), axis=(0, 2)), jnp.mean(jnp.abs(logvar), axis=(0, 2))
