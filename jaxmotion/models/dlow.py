"""DLow (Yuan & Kitani, ECCV 2020): a GRU CVAE and the Q network that maps one noise draw to K latents.

Architecture follows the paper and its released configuration for Human3.6M (`h36m_nsamp50`):
GRU encoders with 128 hidden units over X and Y, a tanh MLP (300, 200) to `mu`/`logvar`
(nz = 128), a decoder GRU initialised by an MLP of `h_x` whose input at each step is
`[h_x, z, y_{t-1}]` (y_0 = the last observed pose), then MLP (300, 200) and a linear output.
The Q network ("NFDiag") encodes X with its own GRU and predicts K affine maps `z_k = a_k * eps + b_k`.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxmotion.losses import dlow_diversity, kld_affine, kld_normal, min_of_k_sq_error
from jaxmotion.nn.gru import GRU, GRUCell, gru_update
from jaxmotion.nn.mlp import MLP


class DLowCVAE(nn.Module):
    """The DLow CVAE over frame vectors `(batch, time, dim)`; `__call__` returns `(y_rec, mu, logvar)`."""

    dim: int
    horizon: int
    nz: int = 128
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (300, 200)

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

    def encode(self, x, y) -> tuple[Float[Array, "b z"], Float[Array, "b z"]]:
        """Returns `(mu, logvar)` of q(z | X, Y)."""
        h = jnp.concatenate([self.encode_x(x), self.e_rnn(y)[:, -1]], axis=-1)
        h = self.e_mlp(h)
        return self.e_mu(h), self.e_logvar(h)

    def decode_step(self, carry, cond):
        """Returns `((h, y_t), y_t)`: one decoder step given `cond = [h_x, z]`."""
        h, y_prev = carry
        h = self.d_cell(h, jnp.concatenate([cond, y_prev], axis=-1))
        y = self.d_out(self.d_mlp(h))
        return (h, y), y

    def decode(self, x: Float[Array, "b t_his d"], z: Float[Array, "b z"], h_x=None) -> Float[Array, "b t_pred d"]:
        """Returns the decoded future `(batch, horizon, dim)` for latents `z` (pass `h_x` to reuse it).

        Computes exactly `decode_step` `horizon` times, with the conditioning's share of the GRU
        input gates, `[h_x, z] @ W_ih[:n_cond]`, computed once instead of at every step: it does
        not change over time, and it is 256 of the 316 input columns (a third of the decoder's FLOPs).
        """
        if h_x is None:
            h_x = self.encode_x(x)
        cond = jnp.concatenate([h_x, z], axis=-1)
        carry = (self.drnn_mlp(h_x), x[:, -1])
        if self.is_initializing():
            self.decode_step(carry, cond)  # creates the decoder's parameters
        w = self.d_cell.variables["params"]
        n_cond = cond.shape[-1]
        gi_cond = cond @ w["weight_ih"][:n_cond] + w["bias_ih"]
        w_y = w["weight_ih"][n_cond:]

        def step(mdl, c, _):
            h, y_prev = c
            h = gru_update(gi_cond + y_prev @ w_y, h @ w["weight_hh"] + w["bias_hh"], h)
            y = mdl.d_out(mdl.d_mlp(h))
            return (h, y), y

        scan = nn.scan(step, variable_broadcast="params", split_rngs={"params": False}, length=self.horizon, out_axes=1)
        _, ys = scan(self, carry, None)
        return ys

    def __call__(self, x, y, key=None):
        """Returns `(y_rec, mu, logvar)`; samples z by reparameterisation when `key` is given, else z = mu."""
        mu, logvar = self.encode(x, y)
        z = mu if key is None else mu + jnp.exp(0.5 * logvar) * jax.random.normal(key, mu.shape)
        return self.decode(x, z), mu, logvar


class DLowQ(nn.Module):
    """DLow's Q network ("NFDiag"): returns `(z (b, nk, nz), a, b)` with `z_k = a_k * eps + b_k`."""

    nz: int = 128
    nk: int = 50
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (1024, 512)

    @nn.compact
    def __call__(self, x: Float[Array, "b t_his d"], eps: Float[Array, "b z"]):
        h = GRU(self.nh_rnn, name="x_rnn")(x)[:, -1]
        h = MLP(self.nh_mlp, name="mlp")(h)
        a = nn.Dense(self.nz * self.nk, name="head_A")(h).reshape(-1, self.nk, self.nz)
        b = nn.Dense(self.nz * self.nk, name="head_b")(h).reshape(-1, self.nk, self.nz)
        return a * eps[:, None, :] + b, a, b


def decode_k(cvae: DLowCVAE, params, x: Float[Array, "b t_his d"], z: Float[Array, "b k z"]) -> Float[Array, "b k t_pred d"]:
    """Returns the K futures decoded from latents `z` (vmapped over K; the past is encoded once)."""
    h_x = cvae.apply(params, x, method=DLowCVAE.encode_x)
    dec = lambda z_k: cvae.apply(params, x, z_k, h_x, method=DLowCVAE.decode)
    return jnp.swapaxes(jax.vmap(dec, in_axes=1)(z), 0, 1)


def sample_prior(cvae: DLowCVAE, params, x, key: jax.Array, k: int) -> Float[Array, "b k t_pred d"]:
    """Returns K futures with latents drawn i.i.d. from N(0, I): the plain CVAE baseline."""
    z = jax.random.normal(key, (x.shape[0], k, cvae.nz))
    return decode_k(cvae, params, x, z)


def sample_dlow(cvae: DLowCVAE, cvae_params, q: DLowQ, q_params, x, key: jax.Array) -> Float[Array, "b nk t_pred d"]:
    """Returns DLow's `nk` futures: one noise draw per window mapped to nk latents by Q (DLow Eq. (4))."""
    eps = jax.random.normal(key, (x.shape[0], cvae.nz))
    z, _, _ = q.apply(q_params, x, eps)
    return decode_k(cvae, cvae_params, x, z)


def cvae_loss(cvae: DLowCVAE, params, batch: Float[Array, "b t d"], key, *, t_his: int, beta: float, lambda_v: float):
    """Returns `(loss, metrics)`: DLow's CVAE objective, summed over time and dims, averaged over the batch.

    loss = ||Y_rec - Y||^2 + lambda_v ||x_{t_his} - y_rec_1||^2 + beta KL(q(z|X,Y) || N(0,I)).
    The middle term penalises a jump between the last observed and the first predicted frame.
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    y_rec, mu, logvar = cvae.apply(params, x, y, key)
    b = batch.shape[0]
    recon = jnp.sum((y_rec - y) ** 2) / b
    jump = jnp.sum((x[:, -1] - y_rec[:, 0]) ** 2) / b
    kld = jnp.sum(kld_normal(mu, logvar)) / b
    return recon + lambda_v * jump + beta * kld, {"recon": recon, "jump": jump, "kld": kld}


def dlow_loss(
    q: DLowQ, q_params, cvae: DLowCVAE, cvae_params, batch, key, *, t_his: int,
    d_scale: float, lambda_j: float, lambda_recon: float, lambda_kl: float,
):
    """Returns `(loss, metrics)`: DLow's Q objective on a frozen decoder (DLow Eq. (8)-(10)).

    loss = lambda_kl KL(N(b_k, a_k^2) || N(0,I)) + lambda_j mean_{i<j} exp(-||y_i - y_j||^2 / d_scale)
           + lambda_recon min_k ||y_k - Y||^2.
    """
    x, y = batch[:, :t_his], batch[:, t_his:]
    eps = jax.random.normal(key, (x.shape[0], cvae.nz))
    z, a, b = q.apply(q_params, x, eps)
    y_g = decode_k(cvae, jax.lax.stop_gradient(cvae_params), x, z)
    kld = jnp.mean(kld_affine(a, b))
    div = jnp.mean(jax.vmap(lambda yk: dlow_diversity(yk, d_scale))(y_g))
    recon = jnp.mean(jax.vmap(min_of_k_sq_error)(y_g, y))
    loss = lambda_kl * kld + lambda_j * div + lambda_recon * recon
    return loss, {"kld": kld, "div": div, "recon": recon}
