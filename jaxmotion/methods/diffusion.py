"""A DCT-space diffusion predictor (HumanMAC class) as a method: one stage that trains the denoiser and its EMA.

Stage `diffusion`: the noise-prediction loss on whole windows (`models.diffusion.diffusion_loss`),
Adam, and the EMA of the weights kept in the same parameters (`{"model", "ema"}`,
`models.diffusion.ema_weights`). Predictors: zero-velocity, and `"diffusion"`: DDIM with DCT
completion from the EMA weights, at `DiffusionConfig.sampling_steps`, for any K.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import optax

from jaxmotion.method import Method, Stage
from jaxmotion.methods.common import execution_of, window_batches, zero_velocity
from jaxmotion.models import diffusion
from jaxmotion.models.diffusion import DiffusionConfig
from jaxmotion.train.loop import lr_schedule


def learning_rate(c: DiffusionConfig) -> optax.Schedule:
    """Returns the lr schedule: constant then linear decay (`lr_fix_fraction`), or the release's step decay (`lr_milestones`)."""
    if not c.lr_milestones:
        return lr_schedule(c.lr, c.num_steps, c.lr_fix_fraction)
    return optax.piecewise_constant_schedule(c.lr, {max(int(round(m * c.num_steps)), 1): c.lr_gamma for m in c.lr_milestones})


def stages(cfg, prep) -> list[Stage]:
    """Returns the one stage: the denoiser trained on `cfg`'s windows, its EMA beside it."""
    ds, c = prep.dataset, METHOD.settings(cfg)
    model = diffusion.denoiser(c, ds.dim, execution_of(cfg))
    abar = diffusion.schedule(c.schedule, c.noise_steps)
    t_total = ds.t_his + ds.t_pred
    if c.n_dct > t_total:
        raise ValueError(f"DiffusionConfig.n_dct ({c.n_dct}) must be at most the window's {t_total} frames")
    if c.complete_frames is not None and c.complete_frames > t_total:
        raise ValueError(f"DiffusionConfig.complete_frames ({c.complete_frames}) must be at most the window's {t_total} frames")
    x = jnp.zeros((1, c.n_dct, ds.dim))

    def init(key, _frozen):
        p = model.init(key, x, jnp.ones((1,), jnp.int32), x, jnp.ones((1,)))
        return {"model": p, "ema": p}

    loss = functools.partial(diffusion.diffusion_loss, model, t_his=ds.t_his, abar=abar, cond_drop=c.cond_drop)
    return [
        Stage(
            name="diffusion",
            init=init,
            optimizer=optax.chain(optax.adam(learning_rate(c)),
                                  diffusion.ema_weights(c.ema_decay, c.ema_start)),
            loss=lambda p, _frozen, batch, key: loss(p["model"], batch, key),
            batches=window_batches(prep, c.batch_size),
            num_steps=c.num_steps, init_seed=cfg.seed, data_seed=cfg.seed,
        )
    ]


def sampler(cfg, ds, params: dict, k: int, sampling_steps: int | None = None):
    """Returns the jitted `(x, key) -> (b, K, t_pred, D)` DDIM sampler of the EMA weights (`sampling_steps`: the config's when None)."""
    c = METHOD.settings(cfg)
    model = diffusion.denoiser(c, ds.dim, execution_of(cfg))
    abar = diffusion.schedule(c.schedule, c.noise_steps)
    steps = c.sampling_steps if sampling_steps is None else sampling_steps
    diffusion.ddim_timesteps(c.noise_steps, steps)  # a clear error for steps that do not divide the schedule
    ema = params["diffusion"]["ema"]
    return jax.jit(lambda x, key: diffusion.sample(model, ema, x, key, k, t_pred=ds.t_pred, abar=abar,
                                                   sampling_steps=steps, complete_frames=c.complete_frames,
                                                   cond_keep=c.test_cond_keep))


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity and the diffusion model (EMA weights)."""
    return {"zero_velocity": zero_velocity(ds.t_pred, k), "diffusion": sampler(cfg, ds, params, k)}


METHOD = Method(
    name="diffusion",
    config_type=DiffusionConfig,
    stages=stages,
    predictors=predictors,
    description="DCT-space diffusion (HumanMAC, Chen et al., ICCV 2023): transformer denoiser, DDIM with DCT completion",
)
