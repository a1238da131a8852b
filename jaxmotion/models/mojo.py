"""MOJO (Zhang, Black & Tang, CVPR 2021, "We are More than Our Joints"): a CVAE with a latent DCT space.

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
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct
from jaxtyping import Array, Float

from jaxmotion.dct import dct, idct
from jaxmotion.losses import dlow_diversity, kld_normal, min_of_k_sq_error, robust_kld
from jaxmotion.nn.gru import GRU, GRUCell, gru_update
from jaxmotion.nn.mlp import MLP


@dataclasses.dataclass
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
    q_num_steps: int = 400
    q_lr_fix_fraction: float = 0.2
    d_scale: float = 100.0
    lambda_j: float = 25.0
    lambda_recon: float = 2.0
    lambda_kl: float = 1.0
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
        if not 0.0 < self.dlow_band_fraction <= 1.0:
            raise ValueError(f"MojoConfig.dlow_band_fraction must be in (0, 1], got {self.dlow_band_fraction}")
        unknown = set(self.baselines) - {"zero_velocity", "mojo_prior", "mojo_proj"}
        if unknown:
            raise ValueError(
                f"MojoConfig.baselines: unknown {sorted(unknown)}; known: zero_velocity, mojo_prior, mojo_proj"
            )
        if self.proj_max_steps < 1:
            raise ValueError(f"MojoConfig.proj_max_steps must be >= 1, got {self.proj_max_steps}")


def num_bands(latent: str, horizon: int) -> int:
    """Returns the number of latent bands: one per future frame for the DCT latent, else 1."""
    return horizon if latent == "dct" else 1


def num_low_bands(cfg: MojoConfig, horizon: int) -> int:
    """Returns L, the number of lowest bands sampled by DLow (at least 1; release: 9 of 45)."""
    return max(1, round(cfg.dlow_band_fraction * num_bands(cfg.latent, horizon)))


class DecodeCarry(NamedTuple):
    """Decoder state between steps: GRU hidden state `h (b, nh)` and the previous frame `y_prev (b, D)`."""

    h: Float[Array, "b h"]
    y_prev: Float[Array, "b d"]


class DecodeInputs(NamedTuple):
    """Per-step decoder inputs: the past code `h_x (b, nh)` and the time-domain latent `z_t (b, nz)`."""

    h_x: Float[Array, "b h"]
    z_t: Float[Array, "b z"]


class MojoCVAE(nn.Module):
    """MOJO's CVAE over frame vectors `(batch, time, dim)`; `__call__` returns `(y_rec, mu, logvar)`.

    `mu`, `logvar` are `(batch, n_bands, nz)`: `n_bands = horizon` DCT bands (latent "dct") or 1.
    """

    dim: int
    horizon: int
    nz: int = 16
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (300, 200)
    latent: str = "dct"
    residual: bool = True

    @property
    def n_bands(self) -> int:
        return num_bands(self.latent, self.horizon)

    def setup(self):
        self.x_rnn = GRU(self.nh_rnn)
        self.e_rnn = GRU(self.nh_rnn)
        self.e_mlp = MLP(self.nh_mlp)
        self.e_mu = nn.Dense(self.nz)
        self.e_logvar = nn.Dense(self.nz)
        self.drnn_mlp = MLP(tuple(self.nh_mlp) + (self.nh_rnn,))
        self.d_cell = GRUCell(self.nh_rnn)
        self.d_mlp = MLP(self.nh_mlp)
        self.d_out = nn.Dense(self.dim)

    def encode_x(self, x: Float[Array, "b t_his d"]) -> Float[Array, "b h"]:
        """Returns the last hidden state of the past encoder GRU."""
        return self.x_rnn(x)[:, -1]

    def encode(self, x, y) -> tuple[Float[Array, "b c z"], Float[Array, "b c z"]]:
        """Returns `(mu, logvar)` of q(z | X, Y), one `nz` Gaussian per band (MOJO Sec. 3.3)."""
        h_x = self.encode_x(x)
        h_y = self.e_rnn(y)  # a hidden state per future frame keeps full temporal resolution
        if self.latent == "dct":
            h = jnp.concatenate([jnp.broadcast_to(h_x[:, None], h_y.shape[:-1] + h_x.shape[-1:]), h_y], axis=-1)
            h = dct(h)  # (b, t_pred bands, 2 nh): frequency bands of the encoder states
        else:
            h = jnp.concatenate([h_x, h_y[:, -1]], axis=-1)[:, None]
        h = self.e_mlp(h)  # the same layers for every band
        return self.e_mu(h), self.e_logvar(h)

    def latent_to_time(self, z: Float[Array, "b c z"]) -> Float[Array, "b t_pred z"]:
        """Returns the per-frame latent: inverse DCT of the bands, or the one vector repeated."""
        if self.latent == "dct":
            return idct(z, self.horizon)
        return jnp.broadcast_to(z, (z.shape[0], self.horizon, z.shape[-1]))

    def decode_init(self, x: Float[Array, "b t_his d"], z: Float[Array, "b c z"], h_x=None):
        """Returns `(carry0, inputs)`: the first decoder state and time-major per-step inputs `(t_pred, b, .)`."""
        if h_x is None:
            h_x = self.encode_x(x)
        z_t = jnp.swapaxes(self.latent_to_time(z), 0, 1)
        inputs = DecodeInputs(jnp.broadcast_to(h_x, (self.horizon,) + h_x.shape), z_t)
        return DecodeCarry(self.drnn_mlp(h_x), x[:, -1]), inputs

    def decode_step(self, carry: DecodeCarry, inputs: DecodeInputs) -> tuple[DecodeCarry, Float[Array, "b d"]]:
        """Returns `(carry', y_t)`: one GRU step on `[h_x, z_t, y_{t-1}]`, plus `y_{t-1}` if residual."""
        h = self.d_cell(carry.h, jnp.concatenate([inputs.h_x, inputs.z_t, carry.y_prev], axis=-1))
        y = self.d_out(self.d_mlp(h))
        if self.residual:
            y = y + carry.y_prev
        return DecodeCarry(h, y), y

    def decode(self, x: Float[Array, "b t_his d"], z: Float[Array, "b c z"], h_x=None) -> Float[Array, "b t_pred d"]:
        """Returns the decoded future `(batch, horizon, dim)` for band latents `z` (pass `h_x` to reuse it).

        Computes exactly `decode_step` `horizon` times, with `h_x`'s share of the GRU input gates,
        `h_x @ W_ih[:nh]`, computed once instead of at every step (it does not change over time).
        `z_t`'s share stays in the loop: precomputing it for all steps materialises a
        `(t_pred, b, 3 nh)` array per sample, which measured slower at batch 64 x K = 50 on CPU.
        """
        carry, inputs = self.decode_init(x, z, h_x)
        if self.is_initializing():
            self.decode_step(carry, jax.tree.map(lambda a: a[0], inputs))  # creates the decoder's parameters
        w = self.d_cell.variables["params"]
        nh = inputs.h_x.shape[-1]
        gi_h = inputs.h_x[0] @ w["weight_ih"][:nh] + w["bias_ih"]  # (b, 3 nh)
        w_zy = w["weight_ih"][nh:]

        def step(mdl, c, z_t):
            gi = gi_h + jnp.concatenate([z_t, c.y_prev], axis=-1) @ w_zy
            h = gru_update(gi, c.h @ w["weight_hh"] + w["bias_hh"], c.h)
            y = mdl.d_out(mdl.d_mlp(h))
            if self.residual:
                y = y + c.y_prev
            return DecodeCarry(h, y), y

        scan = nn.scan(step, variable_broadcast="params", split_rngs={"params": False}, length=self.horizon, out_axes=1)
        _, ys = scan(self, carry, inputs.z_t)
        return ys

    def __call__(self, x, y, key=None):
        """Returns `(y_rec, mu, logvar)`; samples z by reparameterisation when `key` is given, else z = mu."""
        mu, logvar = self.encode(x, y)
        z = mu if key is None else mu + jnp.exp(0.5 * logvar) * jax.random.normal(key, mu.shape)
        return self.decode(x, z), mu, logvar


def cvae_model(cfg: MojoConfig, dim: int, horizon: int) -> MojoCVAE:
    """Returns the CVAE module a `MojoConfig` describes."""
    return MojoCVAE(
        dim=dim, horizon=horizon, nz=cfg.nz, nh_rnn=cfg.nh_rnn, nh_mlp=tuple(cfg.nh_mlp),
        latent=cfg.latent, residual=cfg.residual,
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


def decode_inputs(params: DecoderParams, x: Float[Array, "b t_his d"], z: Float[Array, "b c z"]):
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


class _QTrunk(nn.Module):
    """Returns `(a, b)` each `(batch, n_heads, nk, nz)`: DLow's GRU + MLP trunk and affine heads."""

    nz: int
    nk: int
    n_heads: int
    nh_rnn: int
    nh_mlp: tuple[int, ...]

    @nn.compact
    def __call__(self, x):
        h = GRU(self.nh_rnn, name="x_rnn")(x)[:, -1]
        h = MLP(self.nh_mlp, name="mlp")(h)
        # One Dense with n_heads * nk * nz outputs is exactly n_heads unshared linear heads.
        shape = (-1, self.n_heads, self.nk, self.nz)
        a = nn.Dense(self.n_heads * self.nk * self.nz, name="head_A")(h).reshape(shape)
        b = nn.Dense(self.n_heads * self.nk * self.nz, name="head_b")(h).reshape(shape)
        return a, b


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

    @nn.compact
    def __call__(self, x: Float[Array, "b t_his d"], eps: Float[Array, "b l z"]):
        if self.shared_trunk:
            a, b = _QTrunk(self.nz, self.nk, self.n_low, self.nh_rnn, tuple(self.nh_mlp), name="q")(x)
        else:
            bands = nn.vmap(
                _QTrunk, variable_axes={"params": 0}, split_rngs={"params": True},
                in_axes=None, out_axes=1, axis_size=self.n_low,
            )
            a, b = bands(self.nz, self.nk, 1, self.nh_rnn, tuple(self.nh_mlp), name="q")(x)
            a, b = a[:, :, 0], b[:, :, 0]
        z = jnp.exp(0.5 * a) * eps[:, :, None, :] + b  # (b, L, nk, nz)
        return jnp.swapaxes(z, 1, 2), a, b


def q_model(cfg: MojoConfig, horizon: int, nk: int) -> MojoQ:
    """Returns the per-band DLow module of a `MojoConfig` for `nk` samples."""
    return MojoQ(
        nz=cfg.nz, nk=nk, n_low=num_low_bands(cfg, horizon), nh_rnn=cfg.q_nh_rnn,
        nh_mlp=tuple(cfg.q_nh_mlp), shared_trunk=cfg.q_shared_trunk,
    )


# --------------------------------------------------------------------------------------------
# Samplers.


def decode_k(model: MojoCVAE, params, x: Float[Array, "b t_his d"], z: Float[Array, "b k c z"]) -> Float[Array, "b k t_pred d"]:
    """Returns the K futures decoded from band latents `z` (vmapped over K; the past is encoded once)."""
    h_x = model.apply(params, x, method=MojoCVAE.encode_x)
    dec = lambda z_k: model.apply(params, x, z_k, h_x, method=MojoCVAE.decode)
    return jnp.swapaxes(jax.vmap(dec, in_axes=1)(z), 0, 1)


def sample_prior(model: MojoCVAE, params, x, key: jax.Array, k: int) -> Float[Array, "b k t_pred d"]:
    """Returns K futures with every band's latent drawn i.i.d. from N(0, I) (MOJO's "VAE+DCT" sampler)."""
    z = jax.random.normal(key, (x.shape[0], k, model.n_bands, model.nz))
    return decode_k(model, params, x, z)


def q_latents(model: MojoCVAE, q: MojoQ, q_params, x, key: jax.Array):
    """Returns `(z (b, nk, n_bands, nz), a, b)`: DLow latents on the lowest L bands, N(0, I) above."""
    k_eps, k_high = jax.random.split(key)
    eps = jax.random.normal(k_eps, (x.shape[0], q.n_low, model.nz))
    z_low, a, b = q.apply(q_params, x, eps)
    z_high = jax.random.normal(k_high, (x.shape[0], q.nk, model.n_bands - q.n_low, model.nz))
    return jnp.concatenate([z_low, z_high], axis=2), a, b


def sample_mojo(model: MojoCVAE, params, q: MojoQ, q_params, x, key: jax.Array) -> Float[Array, "b nk t_pred d"]:
    """Returns MOJO's nk futures: per-band DLow on the lowest L bands, N(0, I) on the rest (MOJO Sec. 3.3)."""
    z, _, _ = q_latents(model, q, q_params, x, key)
    return decode_k(model, params, x, z)


# --------------------------------------------------------------------------------------------
# Objectives.


def cvae_loss(model: MojoCVAE, params, batch: Float[Array, "b t d"], key, *, t_his: int, cfg: MojoConfig):
    """Returns `(loss, metrics)`: MOJO Eq. (1) (`cfg.loss="mojo"`) or DLow's CVAE objective (`"dlow"`).

    "mojo": mean|Y - Yrec| + alpha mean|dY - dYrec| + beta Psi(KLD), KLD = 0.5 mean(-1 - logvar +
    mu^2 + exp(logvar)) over batch, bands and dims (the release's element means); Psi only if
    `cfg.robust_kld`. "dlow": sum (Yrec - Y)^2 + lambda_v |x_T - yrec_1|^2 + beta KLD, sums / batch.
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = model.apply(params, x, y, key)
    if cfg.loss == "mojo":
        recon = jnp.mean(jnp.abs(y_rec - y))
        vel = jnp.mean(jnp.abs(jnp.diff(y_rec, axis=1) - jnp.diff(y, axis=1)))
        kld = jnp.mean(kld_normal(mu, logvar)) / mu.shape[-1]
        kl_term = robust_kld(kld) if cfg.robust_kld else kld
        loss = recon + cfg.alpha * vel + cfg.beta * kl_term
        return loss, {"recon": recon, "vel": vel, "kld": kld}
    b = batch.shape[0]
    recon = jnp.sum((y_rec - y) ** 2) / b
    jump = jnp.sum((x[:, -1] - y_rec[:, 0]) ** 2) / b
    kld = jnp.sum(kld_normal(mu, logvar)) / b
    kl_term = robust_kld(kld) if cfg.robust_kld else kld
    return recon + cfg.lambda_v * jump + cfg.beta * kl_term, {"recon": recon, "jump": jump, "kld": kld}


def min_of_k_l1_error(y_k: Float[Array, "k t d"], y: Float[Array, "t d"]) -> Float[Array, ""]:
    """Returns min_k sum_{t,d} |y_k - y|: the release's MOJO reconstruction term for one window."""
    return jnp.min(jnp.sum(jnp.abs(y_k - y[None]), axis=(-2, -1)))


def q_loss(q: MojoQ, q_params, model: MojoCVAE, cvae_params, batch, key, *, t_his: int, cfg: MojoConfig):
    """Returns `(loss, metrics)`: DLow's objective (DLow Eq. (8)-(10)) for the per-band maps on a frozen decoder.

    loss = lambda_kl mean_{b,k,band} KL(N(b, exp(a)) || N(0,I)) + lambda_j mean_{i<j} exp(-||y_i - y_j||^2 / d_scale)
           + lambda_recon min_k ||y_k - Y|| (L1 for MOJO's loss as in the release, squared for DLow's).
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    z, a, b = q_latents(model, q, q_params, x, key)
    y_g = decode_k(model, jax.lax.stop_gradient(cvae_params), x, z)
    kld = jnp.mean(kld_normal(b, a))
    div = jnp.mean(jax.vmap(lambda yk: dlow_diversity(yk, cfg.d_scale))(y_g))
    recon_fn = min_of_k_l1_error if cfg.loss == "mojo" else min_of_k_sq_error
    recon = jnp.mean(jax.vmap(recon_fn)(y_g, y))
    loss = cfg.lambda_kl * kld + cfg.lambda_j * div + cfg.lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}


def latent_spectrum(model: MojoCVAE, params, x, y) -> tuple[Float[Array, " c"], Float[Array, " c"]]:
    """Returns per-band `(mean |mu|, mean |logvar|)` over windows and latent dims (MOJO Fig. S5)."""
    mu, logvar = model.apply(params, x, y, method=MojoCVAE.encode)
    return jnp.mean(jnp.abs(mu), axis=(0, 2)), jnp.mean(jnp.abs(logvar), axis=(0, 2))
