"""DLow as a method: train the CVAE, then one Q network per K on the frozen decoder (DLow Sec. 3-4).

Stages: `cvae` (DLow's CVAE objective), then `dlow_k{K}` for every K of `Config.eval_k` (DLow's
K affine maps are a trained constant, so each K has its own Q network). Predictors: zero-velocity,
the CVAE with N(0, I) latents (`"cvae"`), and DLow.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from jaxmotion.method import Method, Stage
from jaxmotion.methods.common import adam, execution_of, window_batches, zero_velocity
from jaxmotion.models import dlow
from jaxmotion.models.dlow import DLowConfig


def stages(cfg, prep) -> list[Stage]:
    """Returns DLow's stages: the CVAE, then a Q network per K of `cfg.eval_k`."""
    ds, c = prep.dataset, METHOD.settings(cfg)
    cvae = dlow.cvae_model(c.cvae, ds.dim, ds.t_pred, execution_of(cfg))
    x, y = jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, ds.t_pred, ds.dim))
    cvae_loss = functools.partial(dlow.cvae_loss, cvae, t_his=ds.t_his, beta=c.cvae.beta, lambda_v=c.cvae.lambda_v)
    out = [
        Stage(
            name="cvae",
            init=lambda key, _frozen: cvae.init(key, x, y, jax.random.key(0)),
            optimizer=adam(c.cvae.lr, c.cvae.num_steps, c.cvae.lr_fix_fraction),
            loss=lambda p, _frozen, batch, key: cvae_loss(p, batch, key),
            batches=window_batches(prep, c.cvae.batch_size),
            num_steps=c.cvae.num_steps, init_seed=cfg.seed, data_seed=cfg.seed,
        )
    ]
    for nk in cfg.eval_k:
        q = dlow.q_model(c.q, c.cvae.nz, nk, execution_of(cfg))
        q_loss = functools.partial(
            dlow.dlow_loss, q, cvae=cvae, t_his=ds.t_his, d_scale=c.q.d_scale,
            lambda_j=c.q.lambda_j, lambda_recon=c.q.lambda_recon, lambda_kl=c.q.lambda_kl,
        )
        out.append(
            Stage(
                name=f"dlow_k{nk}",
                init=functools.partial(lambda key, _frozen, q: q.init(key, x, jnp.zeros((1, c.cvae.nz))), q=q),
                optimizer=adam(c.q.lr, c.q.num_steps, c.q.lr_fix_fraction),
                loss=functools.partial(
                    lambda p, frozen, batch, key, q_loss: q_loss(p, cvae_params=frozen["cvae"], batch=batch, key=key),
                    q_loss=q_loss,
                ),
                batches=window_batches(prep, c.q.batch_size),
                num_steps=c.q.num_steps, init_seed=cfg.seed + 1, data_seed=cfg.seed + nk, frozen=("cvae",),
            )
        )
    return out


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers for zero-velocity, CVAE and (for a trained K) DLow."""
    c = METHOD.settings(cfg)
    cvae = dlow.cvae_model(c.cvae, ds.dim, ds.t_pred, execution_of(cfg))
    out = {
        "zero_velocity": zero_velocity(ds.t_pred, k),
        "cvae": jax.jit(lambda x, key: dlow.sample_prior(cvae, params["cvae"], x, key, k)),
    }
    if f"dlow_k{k}" in params:
        q, qp = dlow.q_model(c.q, c.cvae.nz, k, execution_of(cfg)), params[f"dlow_k{k}"]
        out["dlow"] = jax.jit(lambda x, key: dlow.sample_dlow(cvae, params["cvae"], q, qp, x, key))
    return out


METHOD = Method(
    name="dlow",
    config_type=DLowConfig,
    stages=stages,
    predictors=predictors,
    description="DLow (Yuan & Kitani, ECCV 2020): GRU CVAE + a Q network per K mapping one noise draw to K latents",
)
