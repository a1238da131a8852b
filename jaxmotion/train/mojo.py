"""MOJO's two training stages (latent-DCT CVAE, then per-band DLow per K) and its samplers, as a method.

Settings live in `cfg.mojo` (a `jaxmotion.models.mojo.MojoConfig`; the default when None). Stages
write `workdir/cvae/` and `workdir/q_k{K}/`. Predictors: `"mojo"` (the config's sampler: DLow on the
lowest L bands, N(0, I) above), and as asked by `MojoConfig.baselines` `"mojo_prior"` (N(0, I) in
every band), `"zero_velocity"` and `"mojo_proj"` (MOJO with recursive projection onto the
dataset's body, `projected_sampler`). `extra_metrics` adds MOJO's realism metrics to evaluation.
"""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion import realism
from jaxmotion.config import Config
from jaxmotion.data.types import MotionDataset
from jaxmotion.models import mojo
from jaxmotion.train.dlow import zero_velocity
from jaxmotion.train.loop import create_state, fit, lr_schedule, make_train_step, restore_params


def mojo_config(cfg: Config) -> mojo.MojoConfig:
    """Returns `cfg.mojo`, or the default `MojoConfig` when unset."""
    m = cfg.mojo if cfg.mojo is not None else mojo.MojoConfig()
    if not isinstance(m, mojo.MojoConfig):
        raise TypeError(f"Config.mojo must be a jaxmotion.models.mojo.MojoConfig, got {type(m).__name__}")
    return m


def cvae_model(cfg: Config, ds: MotionDataset) -> mojo.MojoCVAE:
    return mojo.cvae_model(mojo_config(cfg), ds.dim, ds.t_pred)


def _cvae_state(cfg: Config, ds: MotionDataset):
    m = mojo_config(cfg)
    model = cvae_model(cfg, ds)
    x = jnp.zeros((1, ds.t_his, ds.dim))
    y = jnp.zeros((1, ds.t_pred, ds.dim))
    params = model.init(jax.random.key(cfg.seed), x, y, jax.random.key(0))
    tx = optax.adam(lr_schedule(m.lr, m.num_steps, m.lr_fix_fraction))
    return model, tx, create_state(params, tx)


def _q_state(cfg: Config, ds: MotionDataset, nk: int, cvae_params):
    m = mojo_config(cfg)
    q = mojo.q_model(m, ds.t_pred, nk)
    eps = jnp.zeros((1, q.n_low, m.nz))
    params = q.init(jax.random.key(cfg.seed + 1), jnp.zeros((1, ds.t_his, ds.dim)), eps)
    tx = optax.adam(lr_schedule(m.q_lr, m.q_num_steps, m.q_lr_fix_fraction))
    return q, tx, create_state(params, tx, frozen=cvae_params)


def train_cvae(cfg: Config, prep, workdir: Path, resume: bool = False):
    """Returns the trained CVAE parameters (MOJO Eq. (1), or DLow's objective for VAE+DCT)."""
    ds, m = prep.dataset, mojo_config(cfg)
    model, tx, state = _cvae_state(cfg, ds)
    loss = functools.partial(mojo.cvae_loss, model, t_his=ds.t_his, cfg=m)
    step = make_train_step(lambda p, _frozen, b, k: loss(p, b, k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, m.batch_size), num_steps=m.num_steps,
        workdir=workdir / "cvae", seed=cfg.seed, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc=f"{m.variant} cvae",
    )
    return state.params


def train_q(cfg: Config, prep, cvae_params, nk: int, workdir: Path, resume: bool = False):
    """Returns the per-band DLow parameters for `nk` samples, trained on the frozen decoder."""
    ds, m = prep.dataset, mojo_config(cfg)
    model = cvae_model(cfg, ds)
    q, tx, state = _q_state(cfg, ds, nk, cvae_params)
    loss = functools.partial(mojo.q_loss, q, model=model, t_his=ds.t_his, cfg=m)
    step = make_train_step(lambda p, frozen, b, k: loss(p, cvae_params=frozen, batch=b, key=k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, m.q_batch_size), num_steps=m.q_num_steps,
        workdir=workdir / f"q_k{nk}", seed=cfg.seed + nk, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc=f"{m.variant} q K={nk}",
    )
    return state.params


def train(cfg: Config, prep, workdir: Path, resume: bool = False) -> dict:
    """Returns `{"cvae": params, "q": {K: params}}` after training every stage of the config."""
    cvae_params = train_cvae(cfg, prep, workdir, resume)
    qs = {k: train_q(cfg, prep, cvae_params, k, workdir, resume) for k in cfg.eval_k}
    return {"cvae": cvae_params, "q": qs}


def restore(cfg: Config, prep, workdir: Path) -> dict:
    """Returns the parameters `train` saved in `workdir`."""
    ds = prep.dataset
    _, _, state = _cvae_state(cfg, ds)
    cvae_params = restore_params(workdir / "cvae", state).params
    qs = {}
    for k in cfg.eval_k:
        _, _, qstate = _q_state(cfg, ds, k, cvae_params)
        qs[k] = restore_params(workdir / f"q_k{k}", qstate).params
    return {"cvae": cvae_params, "q": qs}


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: "mojo" and the config's baselines."""
    m = mojo_config(cfg)
    model = cvae_model(cfg, ds)
    out = {}
    if "zero_velocity" in m.baselines:
        out["zero_velocity"] = zero_velocity(ds.t_pred, k)
    if "mojo_prior" in m.baselines:
        out["mojo_prior"] = jax.jit(lambda x, key: mojo.sample_prior(model, params["cvae"], x, key, k))
    if k in params["q"]:
        q = mojo.q_model(m, ds.t_pred, k)
        out["mojo"] = jax.jit(lambda x, key: mojo.sample_mojo(model, params["cvae"], q, params["q"][k], x, key))
        if "mojo_proj" in m.baselines:
            if "body" not in ds.info:
                raise ValueError(
                    f"mojo_proj needs a marker dataset with a body model (info['body']); {ds.name} has none "
                    "(use data_options={'markers': 'bandai'} for Bandai-Namco-2 markers)"
                )
            out["mojo_proj"] = projected_sampler(model, params["cvae"], q, params["q"][k], ds.info["body"], ds.t_his, m.proj_max_steps)
    return out


def projected_sampler(model: mojo.MojoCVAE, cvae_params, q: mojo.MojoQ, q_params, body, t_his: int, max_steps: int = 10):
    """Returns a jitted `(x, key) -> (b, K, t_pred, D)` MOJO sampler with recursive projection (MOJO Sec. 3.4).

    Per window: the body is fitted to the observed markers (shape over all observed frames, then
    fixed); then one `lax.scan` runs decoder step -> Levenberg-Marquardt fit of the body to the
    predicted markers (warm start: the previous frame's fit) -> the fitted markers fed back, for
    the windows' K samples at once (one batch of b * K vmapped fits; nesting a vmap over windows
    around one over samples trips an XLA:CPU verifier error in jax 0.10.2). The latents are the ones
    `sample_mojo` draws for the same key, so "mojo" and "mojo_proj" differ only by the projection.
    Returns the fitted markers: every predicted frame is a valid body of the observed shape.
    """
    from jaxmotion.body.projection import body_fit_fn, init_from_observed, recursive_projection

    dparams = mojo.decoder_params(model, cvae_params)
    fit = body_fit_fn(body, stages=("global", "body", "hands"), max_steps=max_steps)
    m = body.num_markers

    def sample(x, key):
        if x.shape[-1] != 3 * m:
            raise ValueError(f"mojo_proj: frames have {x.shape[-1]} numbers, the body has {m} markers ({3 * m})")
        z, _, _ = mojo.q_latents(model, q, q_params, x, key)
        b, k = z.shape[:2]
        # Windows and samples share one batch axis (b * K): one vmap level over the fits.
        init = jax.vmap(lambda xi: init_from_observed(body, xi.reshape(t_his, m, 3)))(x)
        init_bk = jax.tree.map(lambda a: jnp.repeat(a, k, axis=0), init)
        x_bk = jnp.repeat(x, k, axis=0)
        carry0, inputs = mojo.decode_inputs(dparams, x_bk, z.reshape((b * k,) + z.shape[2:]))
        out = recursive_projection(lambda c, i: mojo.decode_step(dparams, c, i), fit, carry0, inputs, init_bk)
        return jnp.swapaxes(out.markers, 0, 1).reshape(b, k, -1, 3 * m)

    return jax.jit(sample)


def extra_metrics(ds: MotionDataset, pred: np.ndarray, gt: np.ndarray) -> dict[str, np.ndarray]:
    """Returns MOJO's realism metrics per window (`(n,)` arrays) for `pred (n, K, t_pred, D)`, `gt (n, t_pred, D)`.

    FSE always; BDF (bone deformation) when the skeleton names its limb joints; body deformation
    per part and the foot-skating ratio when the frames are global marker positions
    (`ds.info["frames"] == "global"`) with MOJO's marker names. Metrics whose names are missing
    are left out (see `jaxmotion.realism` for what each needs).
    """
    return realism.window_realism(pred, gt, ds)
