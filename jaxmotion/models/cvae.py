"""The GRU CVAE that DLow and MOJO share, and the sampling helpers every CVAE here uses.

DLow's CVAE (Yuan & Kitani 2020) is the one-band case of MOJO's (Zhang et al. 2021):

- Encoder: a GRU over X gives `h_x` (its last state), a GRU over Y gives one state per future
  frame. With a **vector** latent (DLow) `[h_x, h_y,T]` goes through an MLP and two linear layers
  to one `(nz,)` Gaussian; with a **DCT** latent (MOJO Sec. 3.3) `[h_x, h_y,t]` is DCT-transformed
  over the `t_pred` frames and the same layers map every frequency band to its own Gaussian, a
  `(t_pred, nz)` latent.
- Decoder: a GRU cell started from `MLP(h_x)` whose input at step t is `[h_x, z_t, y_{t-1}]`
  (`y_0` = the last observed frame, `z_t` = the inverse DCT of the bands, or z itself), then an
  MLP and a linear layer; with `residual` (MOJO) that layer predicts the change from `y_{t-1}`.

`DLowCVAE` and `MojoCVAE` (in `models/dlow.py`, `models/mojo.py`) are this module with the
papers' defaults. The helpers below (`decode_k`, `sample_prior`) are written once for both; the
reparameterised draw is `jaxmotion.nn.gaussian.reparameterise`, which DivSamp's GCN CVAE shares.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.dct import dct, idct
from jaxmotion.nn.batch import batch_rows
from jaxmotion.nn.decoder_loop import decoder_loop, decoder_scan
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.gaussian import reparameterise
from jaxmotion.nn.gru import GRU, GRUCell
from jaxmotion.nn.linear import Dense
from jaxmotion.nn.mlp import MLP
from jaxmotion.nn.precision import matmul

LATENT_KINDS = ("vector", "dct")


def vmap_k(decode: Callable[[jax.Array], jax.Array], z: Float[ArrayLike, "b k ..."]) -> Float[Array, "b k ..."]:
    """Returns `decode` applied to each of the K latents `z[:, k]`, stacked on axis 1 (one `jax.vmap`, no loop)."""
    return jnp.swapaxes(jax.vmap(decode, in_axes=1)(z), 0, 1)


class DecodeCarry(NamedTuple):
    """Decoder state between steps: GRU hidden state `h (b, nh)` and the previous frame `y_prev (b, D)`."""

    h: Float[ArrayLike, "b h"]
    y_prev: Float[ArrayLike, "b d"]


class DecodeInputs(NamedTuple):
    """Per-step decoder inputs: the past code `h_x (b, nh)` and the time-domain latent `z_t (b, nz)`."""

    h_x: Float[ArrayLike, "b h"]
    z_t: Float[ArrayLike, "b z"]


class GRUCVAE(nn.Module):
    """A GRU CVAE over frame vectors `(batch, time, dim)`; `__call__` returns `(y_rec, mu, logvar)`.

    `mu`, `logvar` are `(batch, nz)` for the vector latent and `(batch, horizon, nz)` (one Gaussian
    per DCT band) for the DCT latent: `latent_shape` says which.
    """

    dim: int
    horizon: int
    nz: int = 128
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (300, 200)
    latent: str = "vector"
    residual: bool = False
    # How it runs (precision, the decoder loop's backward form, remat, unroll): nn/execution.py.
    execution: Execution = Execution()

    @property
    def latent_shape(self) -> tuple[int, ...]:
        return (self.nz,) if self.latent == "vector" else (self.horizon, self.nz)

    @property
    def n_bands(self) -> int:
        return 1 if self.latent == "vector" else self.horizon

    def setup(self):
        if self.latent not in LATENT_KINDS:
            raise ValueError(f"{type(self).__name__}.latent must be one of {LATENT_KINDS}, got {self.latent!r}")
        mm = self.execution.precision  # every layer initialised as the references' PyTorch layers (nn/linear.py, nn/gru.py)
        self.x_rnn = GRU(self.nh_rnn, mm)
        self.e_rnn = GRU(self.nh_rnn, mm)
        self.e_mlp = MLP(self.nh_mlp, precision=mm)
        self.e_mu = Dense(self.nz, precision=mm)
        self.e_logvar = Dense(self.nz, precision=mm)
        self.drnn_mlp = MLP(tuple(self.nh_mlp) + (self.nh_rnn,), precision=mm)
        self.d_cell = GRUCell(self.nh_rnn, mm)
        self.d_mlp = MLP(self.nh_mlp, precision=mm)
        self.d_out = Dense(self.dim, precision=mm)

    def encode_x(self, x: Float[ArrayLike, "b t_his d"]) -> Float[Array, "b h"]:
        """Returns the last hidden state of the past encoder GRU."""
        return self.x_rnn(x, last_only=True)

    def encode(self, x: Float[ArrayLike, "b t_his d"], y: Float[ArrayLike, "b t_pred d"], h_x=None):
        """Returns `(mu, logvar)` of q(z | X, Y): one Gaussian (vector) or one per DCT band (MOJO Sec. 3.3).

        Pass `h_x` (`encode_x(x)`) to reuse it.
        """
        if h_x is None:
            h_x = self.encode_x(x)
        if self.latent == "dct":
            h_y = self.e_rnn(y)  # a hidden state per future frame keeps full temporal resolution
            h = jnp.concatenate([jnp.broadcast_to(h_x[:, None], h_y.shape[:-1] + h_x.shape[-1:]), h_y], axis=-1)
            h = dct(h)  # (b, t_pred bands, 2 nh): frequency bands of the encoder states
        else:
            h = jnp.concatenate([h_x, self.e_rnn(y, last_only=True)], axis=-1)
        h = self.e_mlp(h)  # the same layers for every band
        return self.e_mu(h), self.e_logvar(h)

    def latent_to_time(self, z) -> Float[Array, "b t_pred z"]:
        """Returns the per-frame latent: inverse DCT of the bands, or the one vector repeated."""
        if self.latent == "dct":
            return idct(z, self.horizon)
        return jnp.broadcast_to(z[:, None], (z.shape[0], self.horizon, z.shape[-1]))

    def decode_init(self, x: Float[ArrayLike, "b t_his d"], z, h_x=None) -> tuple[DecodeCarry, DecodeInputs]:
        """Returns `(carry0, inputs)`: the first decoder state and time-major per-step inputs `(t_pred, b, .)`."""
        if h_x is None:
            h_x = self.encode_x(x)
        z_t = jnp.swapaxes(self.latent_to_time(z), 0, 1)
        inputs = DecodeInputs(jnp.broadcast_to(h_x, (self.horizon,) + h_x.shape), z_t)
        return DecodeCarry(self.drnn_mlp(h_x), x[:, -1]), inputs

    def decode_step(self, carry: DecodeCarry, inputs: DecodeInputs) -> tuple[DecodeCarry, Float[Array, "b d"]]:
        """Returns `(carry', y_t)`: one GRU step on `[h_x, z_t, y_{t-1}]`, plus `y_{t-1}` if residual.

        This is the decoder's definition; `decode` computes the same numbers faster (tested equal).
        """
        h = self.d_cell(carry.h, jnp.concatenate([inputs.h_x, inputs.z_t, carry.y_prev], axis=-1))
        y = self.d_out(self.d_mlp(h))
        if self.residual:
            y = y + carry.y_prev
        return DecodeCarry(h, y), y

    def decode(self, x: Float[ArrayLike, "b t_his d"], z, h_x=None) -> Float[Array, "b t_pred d"]:
        """Returns the decoded future `(batch, horizon, dim)` for latents `z` (pass `h_x` to reuse it).

        Computes exactly `decode_step` `horizon` times, with the share of the GRU input gates of
        the inputs that do not change over time computed once: `h_x @ W_ih[:nh]` for the DCT
        latent, `[h_x, z] @ W_ih[:nh + nz]` for the vector latent (for DLow that is 256 of the
        316 input columns, a third of the decoder's FLOPs). Precomputing the DCT latent's `z_t`
        share for all steps materialises a `(t_pred, b, 3 nh)` array per sample, which measured
        slower at batch 64 x K = 50 on CPU, so it stays in the loop.
        """
        carry, inputs = self.decode_init(x, z, h_x)
        if self.is_initializing():
            self.decode_step(carry, jax.tree.map(lambda a: a[0], inputs))  # creates the decoder's parameters
        w = self.d_cell.variables["params"]
        h_x = inputs.h_x[0]
        static = h_x if self.latent == "dct" else jnp.concatenate([h_x, z], axis=-1)
        n_static = static.shape[-1]
        ex = self.execution
        mm = ex.precision
        gi_static = matmul(static, w["weight_ih"][:n_static], mm) + w["bias_ih"]  # (b, 3 nh)
        w_dyn = w["weight_ih"][n_static:]
        mlp, out = self.d_mlp.variables["params"], self.d_out.variables["params"]
        p = {"w_dyn": w_dyn, "w_hh": w["weight_hh"], "b_hh": w["bias_hh"],
             "mlp": [(mlp[f"dense_{i}"]["kernel"], mlp[f"dense_{i}"]["bias"]) for i in range(len(self.nh_mlp))],
             "out": (out["kernel"], out["bias"])}
        per_step = inputs.z_t if self.latent == "dct" else jnp.zeros((self.horizon, static.shape[0], 0), gi_static.dtype)
        if ex.decoder_backward == "batched" and mm == "float32":
            ys = decoder_loop(p, gi_static, carry.h, carry.y_prev, per_step, residual=self.residual)
        else:
            ys = decoder_scan(p, gi_static, carry.h, carry.y_prev, per_step, residual=self.residual, precision=mm,
                              remat=ex.decoder_remat, unroll=ex.decoder_unroll)
        return jnp.swapaxes(ys, 0, 1)

    def __call__(self, x, y, key: jax.Array | None = None):
        """Returns `(y_rec, mu, logvar)`; samples z by reparameterisation when `key` is given, else z = mu.

        The past is encoded once and its code `h_x` given to both the encoder and the decoder. XLA
        merges two identical forward scans, but their gradients stay two backward loops over the past
        (one per use); one `h_x` sums the two cotangents before the single backward scan.
        """
        h_x = self.encode_x(x)
        mu, logvar = self.encode(x, y, h_x)
        return self.decode(x, reparameterise(mu, logvar, key), h_x), mu, logvar


def decode_k(model: GRUCVAE, params, x: Float[ArrayLike, "b t_his d"], z) -> Float[Array, "b k t_pred d"]:
    """Returns the K futures decoded from latents `z (b, K) + latent_shape` (vmapped over K; the past is encoded once)."""
    h_x = model.apply(params, x, method=GRUCVAE.encode_x)
    return vmap_k(lambda z_k: model.apply(params, x, z_k, h_x, method=GRUCVAE.decode), z)


def sample_prior(model: GRUCVAE, params, x: Float[ArrayLike, "b t_his d"], key: jax.Array, k: int) -> Float[Array, "b k t_pred d"]:
    """Returns K futures with latents drawn i.i.d. from N(0, I): the plain CVAE sampler (DLow's "CVAE" row, MOJO's VAE+DCT).

    Args:
        model: the CVAE (`DLowCVAE`, `MojoCVAE`, ...).
        params: its trained variables.
        x: observed frames `(b, t_his, D)`, metres, root-relative.
        key: a `jax.random` key; one draw of `(b, K) + model.latent_shape` latents.
        k: the number of futures K.

    Returns:
        `(b, K, t_pred, D)` futures, vmapped over K (the past is encoded once).
    """
    z = batch_rows(lambda n: jax.random.normal(key, (n, k) + model.latent_shape), x.shape[0])
    return decode_k(model, params, x, z)


def cvae_objective(
    y_rec: Float[ArrayLike, "b t_pred d"], y: Float[ArrayLike, "b t_pred d"], x_last: Float[ArrayLike, "b d"], kld: Float[ArrayLike, ""],
    *, beta: float, lambda_v: float,
) -> tuple[Float[Array, ""], dict]:
    """Returns `(loss, metrics)`: DLow's CVAE objective for a batch whose KL term (summed per window, averaged) is `kld`.

    loss = ||Y_rec - Y||^2 + lambda_v ||x_{t_his} - y_rec_1||^2 + beta KL, squared norms summed
    over time and dims and averaged over the batch. The middle term penalises a jump between the
    last observed and the first predicted frame. (MOJO's VAE+DCT variant passes a robust KL.)
    """
    b = y.shape[0]
    recon = jnp.sum((y_rec - y) ** 2) / b
    jump = jnp.sum((x_last - y_rec[:, 0]) ** 2) / b
    return recon + lambda_v * jump + beta * kld, {"recon": recon, "jump": jump}
