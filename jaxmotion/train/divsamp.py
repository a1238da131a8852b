"""DivSamp's two training stages (GCN CVAE, then the sampler on the frozen decoder) and its predictors.

Method module interface: `train`, `restore`, `predictors` (see jaxmotion/train/dlow.py).

BatchNorm statistics: each stage's `TrainState.params` is the full Flax variable dict
`{"params": ..., "batch_stats": ...}`, so checkpoints and resume carry the running averages with
the weights. The optimiser only touches `"params"` (`optax.multi_transform` with `set_to_zero` on
`"batch_stats"`, which therefore holds no Adam moments), and the train step (`loop.make_bn_train_step`)
writes the statistics returned by the loss (`mutable=["batch_stats"]`) into the new state. In the
sampler stage the CVAE's variables, statistics included, are the loop's `frozen` input and the
decoder runs in evaluation mode (running averages), as the release's `model_t1.eval()`.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import optax

from jaxmotion.config import Config
from jaxmotion.data.types import MotionDataset
from jaxmotion.models import divsamp
from jaxmotion.models.divsamp import DivSampConfig
from jaxmotion.train.dlow import zero_velocity
from jaxmotion.train.loop import bn_optimizer, create_state, fit, lr_schedule, make_bn_train_step, restore_params  # noqa: E501

# `bn_optimizer` and `make_bn_train_step` live in train/loop.py (any BatchNorm model); importable from here too.


def get_divsamp_config(cfg: Config) -> DivSampConfig:
    """Returns the checked `cfg.divsamp` (the defaults when it is None)."""
    return divsamp.check_config(cfg.divsamp if cfg.divsamp is not None else DivSampConfig())


def _dummy_nodes(ds: MotionDataset, d: DivSampConfig):
    return jnp.zeros((2, ds.dim // 3, 3 * d.n_dct), jnp.float32)


def _cvae_state(cfg: Config, ds: MotionDataset):
    d = get_divsamp_config(cfg)
    model = divsamp.cvae_from_config(d)
    cx = _dummy_nodes(ds, d)
    variables = model.init(jax.random.key(cfg.seed), cx, cx, jax.random.key(0), train=False)
    inner = optax.chain(
        optax.clip_by_global_norm(d.cvae_grad_clip),
        optax.adam(lr_schedule(d.cvae_lr, d.cvae_num_steps, d.cvae_lr_fix_fraction)),
    )
    tx = bn_optimizer(inner)
    return model, tx, create_state(dict(variables), tx)


def _sampler_state(cfg: Config, ds: MotionDataset, cvae_variables, d: DivSampConfig | None = None):
    d = d or get_divsamp_config(cfg)
    model = divsamp.sampler_from_config(d)
    variables = model.init(jax.random.key(cfg.seed + 1), _dummy_nodes(ds, d), jax.random.key(0), 2, train=False)
    tx = bn_optimizer(optax.adam(lr_schedule(d.lr, d.num_steps, d.lr_fix_fraction)))
    return model, tx, create_state(dict(variables), tx, frozen=cvae_variables)


def train_cvae(cfg: Config, prep, workdir: Path, resume: bool = False):
    """Returns the trained CVAE variables `{"params", "batch_stats"}` (DivSamp's first stage)."""
    ds = prep.dataset
    d = get_divsamp_config(cfg)
    model, tx, state = _cvae_state(cfg, ds)
    loss = functools.partial(
        divsamp.cvae_loss, model, t_his=ds.t_his, parents=tuple(ds.skeleton.parents), beta=d.beta,
        lambda_v=d.lambda_v, lambda_his=d.lambda_his, lambda_limb=d.lambda_limb,
    )
    step = make_bn_train_step(lambda v, _frozen, b, k: loss(v, b, k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, d.cvae_batch_size), num_steps=d.cvae_num_steps,
        workdir=Path(workdir) / "cvae", seed=cfg.seed, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc="divsamp cvae",
    )
    return state.params


def train_sampler(
    cfg: Config, prep, cvae_variables, workdir: Path, resume: bool = False, d: DivSampConfig | None = None,
    stage: str = "sampler",
):
    """Returns the trained sampler variables on the frozen CVAE, in `workdir/<stage>` (`d` overrides `cfg.divsamp`)."""
    ds = prep.dataset
    d = divsamp.check_config(d) if d is not None else get_divsamp_config(cfg)
    cvae = divsamp.cvae_from_config(d)
    model, tx, state = _sampler_state(cfg, ds, cvae_variables, d)
    loss = functools.partial(
        divsamp.sampler_loss, model, cvae=cvae, t_his=ds.t_his, k=d.nk, lambda_kl=d.lambda_kl,
        lambda_acc=d.lambda_acc, lambda_div=d.lambda_div, eta=d.eta, diversity=d.diversity, d_scale=d.d_scale,
    )
    step = make_bn_train_step(lambda v, frozen, b, k: loss(v, cvae_variables=frozen, batch=b, key=k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, d.batch_size), num_steps=d.num_steps,
        workdir=Path(workdir) / stage, seed=cfg.seed + 1, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc=f"divsamp {stage}",
    )
    return state.params


def train(cfg: Config, prep, workdir: Path, resume: bool = False) -> dict:
    """Returns `{"cvae": variables, "sampler": variables}` after training both stages."""
    cvae_variables = train_cvae(cfg, prep, workdir, resume)
    return {"cvae": cvae_variables, "sampler": train_sampler(cfg, prep, cvae_variables, workdir, resume)}


def restore(cfg: Config, prep, workdir: Path, stage: str = "sampler", d: DivSampConfig | None = None) -> dict:
    """Returns the variables saved by `train` in `workdir` (`stage`, `d`: another sampler run, e.g. an ablation)."""
    ds = prep.dataset
    _, _, state = _cvae_state(cfg, ds)
    cvae_variables = restore_params(Path(workdir) / "cvae", state).params
    _, _, sstate = _sampler_state(cfg, ds, cvae_variables, d)
    return {"cvae": cvae_variables, "sampler": restore_params(Path(workdir) / stage, sstate).params}


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int, d: DivSampConfig | None = None) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity, the CVAE from N(0, I), DivSamp.

    DivSamp draws any K from the same trained sampler (its K is a call argument, not a constant).
    """
    d = d or get_divsamp_config(cfg)
    cvae = divsamp.cvae_from_config(d)
    sampler = divsamp.sampler_from_config(d)
    t_pred = ds.t_pred
    return {
        "zero_velocity": zero_velocity(t_pred, k),
        "divsamp_cvae": jax.jit(lambda x, key: divsamp.sample_prior(cvae, params["cvae"], x, key, k, t_pred=t_pred)),
        "divsamp": jax.jit(
            lambda x, key: divsamp.sample_divsamp(cvae, params["cvae"], sampler, params["sampler"], x, key, k, t_pred=t_pred)
        ),
    }
