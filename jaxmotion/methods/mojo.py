"""MOJO as a method: the latent-DCT CVAE, then per-band DLow per K on the frozen decoder (MOJO Sec. 3.3-3.4).

Settings: `Config.method_config`, a `jaxmotion.models.mojo.MojoConfig`. Stages: `cvae` (MOJO
Eq. (1), or DLow's objective for VAE+DCT), then `q_k{K}` for every K of `Config.eval_k`.
Predictors: `"mojo"` (DLow on the lowest L bands, N(0, I) above) and, as `MojoConfig.baselines`
asks, `"mojo_prior"` (N(0, I) in every band), `"zero_velocity"` and `"mojo_proj"` (MOJO with
recursive projection onto the dataset's body, `projected_sampler`). Evaluation adds MOJO's realism
metrics (`jaxmotion.eval.realism`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from jaxmotion.eval import realism
from jaxmotion.body.projection import body_fit_fn, init_from_observed, recursive_projection
from jaxmotion.method import ExtraMetrics, Method, Stage
from jaxmotion.methods.common import adam, execution_of, window_batches, zero_velocity
from jaxmotion.models import mojo
from jaxmotion.models.mojo import MojoConfig


def stages(cfg, prep) -> list[Stage]:
    """Returns MOJO's stages: the CVAE, then the per-band DLow maps for each K of `cfg.eval_k` (none if `q_num_steps` is 0)."""
    ds, m = prep.dataset, METHOD.settings(cfg)
    model = mojo.cvae_model(m, ds.dim, ds.t_pred, execution_of(cfg))
    x, y = jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, ds.t_pred, ds.dim))
    cvae_loss = functools.partial(mojo.cvae_loss, model, t_his=ds.t_his, **mojo.cvae_loss_weights(m))
    out = [
        Stage(
            name="cvae",
            init=lambda key, _frozen: model.init(key, x, y, jax.random.key(0)),
            optimizer=adam(m.lr, m.num_steps, m.lr_fix_fraction),
            loss=lambda p, _frozen, batch, key: cvae_loss(p, batch, key),
            batches=window_batches(prep, m.batch_size),
            num_steps=m.num_steps, init_seed=cfg.seed, data_seed=cfg.seed,
        )
    ]
    # q_num_steps = 0: no Q stage, the CVAE alone (MOJO's "VAE+DCT" row, sampled as "mojo_prior").
    for nk in cfg.eval_k if m.q_num_steps > 0 else ():
        q = mojo.q_model(m, ds.t_pred, nk, execution_of(cfg))
        q_loss = functools.partial(mojo.q_loss, q, model=model, t_his=ds.t_his, **mojo.q_loss_weights(m))
        out.append(
            Stage(
                name=f"q_k{nk}",
                init=functools.partial(lambda key, _frozen, q: q.init(key, x, jnp.zeros((1, q.n_low, m.nz))), q=q),
                optimizer=adam(m.q_lr, m.q_num_steps, m.q_lr_fix_fraction),
                loss=functools.partial(
                    lambda p, frozen, batch, key, q_loss: q_loss(p, cvae_params=frozen["cvae"], batch=batch, key=key),
                    q_loss=q_loss,
                ),
                batches=window_batches(prep, m.q_batch_size),
                num_steps=m.q_num_steps, init_seed=cfg.seed + 1, data_seed=cfg.seed + nk, frozen=("cvae",),
            )
        )
    return out


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: "mojo" (for a trained K) and the config's baselines."""
    m = METHOD.settings(cfg)
    model = mojo.cvae_model(m, ds.dim, ds.t_pred, execution_of(cfg))
    out = {}
    if "zero_velocity" in m.baselines:
        out["zero_velocity"] = zero_velocity(ds.t_pred, k)
    if "mojo_prior" in m.baselines:
        out["mojo_prior"] = jax.jit(lambda x, key: mojo.sample_prior(model, params["cvae"], x, key, k))
    if f"q_k{k}" in params:
        q, qp = mojo.q_model(m, ds.t_pred, k, execution_of(cfg)), params[f"q_k{k}"]
        out["mojo"] = jax.jit(lambda x, key: mojo.sample_mojo(model, params["cvae"], q, qp, x, key))
        if "mojo_proj" in m.baselines:
            if "body" not in ds.info:
                raise ValueError(
                    f"mojo_proj needs a marker dataset with a body model (info['body']); {ds.name} has none "
                    "(use data_options={'markers': 'bandai'} for Bandai-Namco-2 markers)"
                )
            out["mojo_proj"] = projected_sampler(model, params["cvae"], q, qp, ds.info["body"], ds.t_his, m.proj_max_steps)
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


def extra_metrics(cfg, ds, params: dict) -> ExtraMetrics:
    """Returns MOJO's realism metrics per window (`jaxmotion.eval.realism.window_realism`): FSE always; BDF, body
    deformation and foot skating where the dataset names the joints or markers they need."""
    return ExtraMetrics(lambda pred, gt: realism.window_realism(pred, gt, ds))


METHOD = Method(
    name="mojo",
    config_type=MojoConfig,
    stages=stages,
    predictors=predictors,
    extra_metrics=extra_metrics,
    curve_skip=("zero_velocity", "mojo_proj"),  # mojo_proj: a body fit per frame, too slow to run every N steps
    description="MOJO (Zhang, Black & Tang, CVPR 2021): latent-DCT CVAE, robust KLD, per-band DLow, recursive projection",
)
