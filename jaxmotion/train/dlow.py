"""DLow's two training stages (CVAE, then one Q network per K) and its samplers, as a method.

A method module provides `train(cfg, prep, workdir, resume) -> params`,
`restore(cfg, prep, workdir) -> params` and `predictors(cfg, ds, params, k) -> {name: fn}`,
where each `fn(x (b, t_his, D), key) -> (b, K, t_pred, D)` is jitted. The predictors include the
baselines a method is compared against (here zero-velocity and the CVAE sampled from N(0, I)).
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import optax

from jaxmotion.config import Config
from jaxmotion.data.types import MotionDataset
from jaxmotion.models import dlow
from jaxmotion.train.loop import create_state, fit, lr_schedule, make_train_step, restore_params


def zero_velocity(t_pred: int, k: int):
    """Returns a predictor that repeats the last observed pose: the zero-velocity baseline."""
    return jax.jit(lambda x, key: jnp.broadcast_to(x[:, None, -1:], (x.shape[0], k, t_pred, x.shape[-1])))


def cvae_model(cfg: Config, ds: MotionDataset) -> dlow.DLowCVAE:
    c = cfg.cvae
    return dlow.DLowCVAE(dim=ds.dim, horizon=ds.t_pred, nz=c.nz, nh_rnn=c.nh_rnn, nh_mlp=tuple(c.nh_mlp))


def q_model(cfg: Config, nk: int) -> dlow.DLowQ:
    d = cfg.dlow
    return dlow.DLowQ(nz=cfg.cvae.nz, nk=nk, nh_rnn=d.nh_rnn, nh_mlp=tuple(d.nh_mlp))


def _cvae_state(cfg: Config, ds: MotionDataset):
    model = cvae_model(cfg, ds)
    x = jnp.zeros((1, ds.t_his, ds.dim))
    y = jnp.zeros((1, ds.t_pred, ds.dim))
    params = model.init(jax.random.key(cfg.seed), x, y, jax.random.key(0))
    c = cfg.cvae
    tx = optax.adam(lr_schedule(c.lr, c.num_steps, c.lr_fix_fraction))
    return model, tx, create_state(params, tx)


def _q_state(cfg: Config, ds: MotionDataset, nk: int, cvae_params):
    model = q_model(cfg, nk)
    params = model.init(jax.random.key(cfg.seed + 1), jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, cfg.cvae.nz)))
    d = cfg.dlow
    tx = optax.adam(lr_schedule(d.lr, d.num_steps, d.lr_fix_fraction))
    return model, tx, create_state(params, tx, frozen=cvae_params)


def train_cvae(cfg: Config, prep, workdir: Path, resume: bool = False):
    """Returns the trained CVAE parameters (DLow's first stage)."""
    ds = prep.dataset
    model, tx, state = _cvae_state(cfg, ds)
    c = cfg.cvae
    loss = functools.partial(dlow.cvae_loss, model, t_his=ds.t_his, beta=c.beta, lambda_v=c.lambda_v)
    step = make_train_step(lambda p, _frozen, b, k: loss(p, b, k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, c.batch_size), num_steps=c.num_steps,
        workdir=workdir / "cvae", seed=cfg.seed, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc="cvae",
    )
    return state.params


def train_dlow(cfg: Config, prep, cvae_params, nk: int, workdir: Path, resume: bool = False):
    """Returns the trained Q-network parameters for `nk` samples, on the frozen CVAE decoder."""
    ds = prep.dataset
    cvae = cvae_model(cfg, ds)
    q, tx, state = _q_state(cfg, ds, nk, cvae_params)
    d = cfg.dlow
    loss = functools.partial(
        dlow.dlow_loss, q, cvae=cvae, t_his=ds.t_his, d_scale=d.d_scale,
        lambda_j=d.lambda_j, lambda_recon=d.lambda_recon, lambda_kl=d.lambda_kl,
    )
    step = make_train_step(lambda p, frozen, b, k: loss(p, cvae_params=frozen, batch=b, key=k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, d.batch_size), num_steps=d.num_steps,
        workdir=workdir / f"dlow_k{nk}", seed=cfg.seed + nk, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc=f"dlow K={nk}",
    )
    return state.params


def train(cfg: Config, prep, workdir: Path, resume: bool = False) -> dict:
    """Returns `{"cvae": params, "dlow": {K: params}}` after training every stage of the config."""
    cvae_params = train_cvae(cfg, prep, workdir, resume)
    qs = {k: train_dlow(cfg, prep, cvae_params, k, workdir, resume) for k in cfg.eval_k}
    return {"cvae": cvae_params, "dlow": qs}


def restore(cfg: Config, prep, workdir: Path) -> dict:
    """Returns the parameters `train` saved in `workdir`."""
    ds = prep.dataset
    _, _, state = _cvae_state(cfg, ds)
    cvae_params = restore_params(workdir / "cvae", state).params
    qs = {}
    for k in cfg.eval_k:
        _, _, qstate = _q_state(cfg, ds, k, cvae_params)
        qs[k] = restore_params(workdir / f"dlow_k{k}", qstate).params
    return {"cvae": cvae_params, "dlow": qs}


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers for zero-velocity, CVAE and DLow."""
    cvae = cvae_model(cfg, ds)
    out = {
        "zero_velocity": zero_velocity(ds.t_pred, k),
        "cvae": jax.jit(lambda x, key: dlow.sample_prior(cvae, params["cvae"], x, key, k)),
    }
    if k in params["dlow"]:
        q = q_model(cfg, k)
        out["dlow"] = jax.jit(lambda x, key: dlow.sample_dlow(cvae, params["cvae"], q, params["dlow"][k], x, key))
    return out
