"""GSPS as a method: the pose prior, the measured angle limits, then the part-sequential generator (GSPS Sec. 3).

Settings: `Config.method_config`, a `jaxmotion.models.gsps.GSPSConfig`. Stages, in order:
`prior` (the normalizing flow, maximum likelihood on single training frames, release
`train_nf.py`); `angle_bounds` (computed, not trained: the cosine bounds measured on the
training poses, checkpointed so the generator and evaluation use the same numbers); `generator`
(release `train.py`, the prior and the bounds frozen). Predictors: `zero_velocity` and `gsps`
(any K, i.i.d. noise per part). `sample_part_control` fixes some parts' noise and varies the rest
(`jaxmotion sample --fix-part`). Evaluation adds, per window, the fraction of predicted frames
outside the run's own angle bounds, the pose-prior NLL under its own prior and the bone
deformation (`extra_metrics`, `jaxmotion.eval.validity`), and writes the bounds into every record's
config (`ExtraMetrics.record`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion.eval import validity
from jaxmotion.method import ExtraMetrics, Method, Stage
from jaxmotion.methods.common import execution_of, zero_velocity
from jaxmotion.models import gsps
from jaxmotion.models.gsps import GSPSConfig
from jaxmotion.nn.execution import Execution
from jaxmotion.train.loop import bn_optimizer, lr_schedule


def settings(cfg) -> GSPSConfig:
    """Returns `cfg.method_config` (the defaults when it is None); `GSPSConfig` checks itself when made."""
    return METHOD.settings(cfg)


def _skeleton(ds, c: GSPSConfig):
    names, parents = tuple(ds.skeleton.names), tuple(int(p) for p in ds.skeleton.parents)
    return parents, gsps.angle_roles(names, parents), gsps.body_parts(names, parents, c.parts)


def _models(ds, c: GSPSConfig, execution: Execution = Execution()):
    parents, roles, parts = _skeleton(ds, c)
    prior = gsps.PosePrior(dim=ds.dim, n_layers=c.prior_layers)
    gen = gsps.GSPSGenerator(parts=parts, hidden=c.hidden, num_stage=c.num_stage, execution=execution)
    return prior, gen, parents, roles, parts


def bounds_frames(frames: list[np.ndarray], n: int) -> np.ndarray:
    """Returns `(n, d)`: `n` evenly spaced training frames of the `(T_i, d)` sequences (all when fewer): what the angle bounds are measured on."""
    allf = np.concatenate(frames)
    return allf[np.linspace(0, len(allf) - 1, min(n, len(allf))).round().astype(int)]


def stages(cfg, prep) -> list[Stage]:
    """Returns GSPS's stages: `prior`, `angle_bounds` (computed), `generator`."""
    ds, c = prep.dataset, settings(cfg)
    prior, gen, parents, roles, parts = _models(ds, c, execution_of(cfg))
    frames = np.concatenate(prep.sampler.frames)

    prior_stage = Stage(
        name="prior",
        init=lambda key, _frozen: prior.init(key, jnp.zeros((1, ds.dim))),
        optimizer=optax.chain(
            optax.add_decayed_weights(c.prior_weight_decay),
            optax.adam(lr_schedule(c.prior_lr, c.prior_num_steps, c.prior_lr_fix_fraction)),
        ),
        loss=lambda p, _frozen, batch, key: gsps.prior_loss(prior, p, batch, parents=parents),
        batches=lambda rng: frames[rng.integers(0, len(frames), c.prior_batch_size)],
        num_steps=c.prior_num_steps, init_seed=cfg.seed, data_seed=cfg.seed,
    )
    bounds_stage = Stage(
        name="angle_bounds",
        init=lambda key, _frozen: {"bounds": jnp.asarray(gsps.measure_angle_bounds(
            bounds_frames(prep.sampler.frames, c.angle_bounds_frames), roles, c.angle_percentile, c.angle_margin))},
        optimizer=optax.set_to_zero(), loss=None, batches=None, num_steps=0,
    )

    pool = gsps.candidate_pool(prep.sampler.frames, ds.t_his, ds.t_pred, c.mm_candidate_stride)

    def batches(rng):
        w = prep.sampler.sample(rng, c.batch_size)
        mm, mask = gsps.pseudo_futures(
            w, pool, rng, t_his=ds.t_his, his_threshold=c.mm_his_threshold, pred_threshold=c.mm_pred_threshold, num=c.mm_num
        )
        return {"window": w, "mm": mm, "mm_mask": mask.astype(np.float32)}

    loss = functools.partial(
        gsps.generator_loss, gen, prior=prior, t_his=ds.t_his, parents=parents, parts=parts, roles=roles, n_pre=c.n_pre,
        nz=c.nz, nk1=c.nk1, nk2=c.nk2, lambda_his=c.lambda_his, lambda_limb=c.lambda_limb,
        lambda_div_first=c.lambda_div_first, lambda_div_rest=c.lambda_div_rest, alpha=c.alpha, beta=c.beta,
        lambda_recon=c.lambda_recon, lambda_recon_mm=c.lambda_recon_mm, lambda_prior=c.lambda_prior,
        prior_stride=c.prior_stride, lambda_angle=c.lambda_angle,
    )
    nodes = jnp.zeros((2, ds.dim // 3, 3 * c.n_pre))
    gen_stage = Stage(
        name="generator",
        init=lambda key, _frozen: dict(gen.init(key, nodes, jnp.zeros((2, len(parts), c.nz)), train=False)),
        optimizer=bn_optimizer(optax.chain(
            optax.clip_by_global_norm(c.grad_clip), optax.adam(lr_schedule(c.lr, c.num_steps, c.lr_fix_fraction))
        )),
        loss=lambda v, frozen, batch, key: loss(
            v, prior_params=frozen["prior"], angle_bounds=frozen["angle_bounds"]["bounds"], batch=batch, key=key
        ),
        batches=batches,
        num_steps=c.num_steps, init_seed=cfg.seed + 1, data_seed=cfg.seed + 1, frozen=("prior", "angle_bounds"),
        batch_norm=True,
    )
    return [prior_stage, bounds_stage, gen_stage]


def sample_gsps(c: GSPSConfig, ds, gen_variables, x, key: jax.Array, k: int, noise=None, execution: Execution = Execution()):
    """Returns `(b, K, t_pred, D)` futures; `noise (b, K, P, nz)` defaults to i.i.d. N(0, I) per part."""
    _, gen, _, _, parts = _models(ds, c, execution)
    z = gsps.sample_noise(key, x.shape[0], k, len(parts), c.nz) if noise is None else noise
    seq, _ = gsps.generate(gen, gen_variables, x, z, t_pred=ds.t_pred, n_pre=c.n_pre, train=False)
    return seq[:, :, ds.t_his :]


def sample_part_control(cfg, ds, params: dict, x, key: jax.Array, k: int, fix: tuple[str, ...] = ("lower",)):
    """Returns `(b, K, t_pred, D)` futures whose parts named in `fix` share one noise draw and the rest vary.

    Part names: `gsps.PART_NAMES[parts]` ("lower", "upper"; or "torso", "right_leg", ...). Fixing
    "lower" gives K upper-body motions over one lower-body motion: the lower body is predicted
    first and later parts never overwrite it, so it is identical across the K samples (the
    release's `eval.py --fixlower`). A later part ("upper") shares its noise only: its GCN reads
    the earlier parts' motion, which varies, so its own motion still varies with them.
    """
    c = settings(cfg)
    names = gsps.PART_NAMES[c.parts]
    bad = [f for f in fix if f not in names]
    if bad:
        raise ValueError(f"sample_part_control: unknown part(s) {bad}; GSPSConfig.parts={c.parts!r} has {names}")
    fixed = tuple(names.index(f) for f in fix)

    @jax.jit
    def sample(x, key):
        z = gsps.part_control_noise(key, x.shape[0], k, len(names), c.nz, fixed)
        return sample_gsps(c, ds, params["generator"], x, key, k, noise=z, execution=execution_of(cfg))

    return sample(jnp.asarray(x), key)


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity and GSPS."""
    c = settings(cfg)
    out = {"zero_velocity": zero_velocity(ds.t_pred, k)}
    if "generator" in params:
        v = params["generator"]
        out["gsps"] = jax.jit(lambda x, key: sample_gsps(c, ds, v, x, key, k, execution=execution_of(cfg)))
    return out


def extra_metrics(cfg, ds, params: dict) -> ExtraMetrics:
    """Returns GSPS's extra metrics for a trained run: per window `angle_violation` under the run's own
    `angle_bounds` stage, `prior_nll` / `prior_nll_z` under its `prior` stage, and `BDF` (`jaxmotion.eval.validity`);
    the record says which bounds the evaluation used and how they were measured."""
    v = validity.from_gsps_run(cfg, ds, params)
    return ExtraMetrics(lambda pred, _gt: validity.window_validity(v, pred), _bounds_record(cfg, params))


def _bounds_record(cfg, params: dict) -> dict:
    c = settings(cfg)
    return {"angle_bounds": {
        "measured": f"percentiles {c.angle_percentile} / {100 - c.angle_percentile} of the cosines over up to "
                    f"{c.angle_bounds_frames} evenly spaced training frames, widened by {c.angle_margin}",
        "applies": "lo where lo >= -0.98, hi where hi <= 0.98",
        "bounds": validity.bounds_record(params["angle_bounds"]["bounds"]),
    }}


METHOD = Method(
    name="gsps",
    config_type=GSPSConfig,
    stages=stages,
    predictors=predictors,
    extra_metrics=extra_metrics,
    part_control=sample_part_control,
    description="GSPS (Mao et al., ICCV 2021): flow pose prior, angle limits, body parts generated in sequence by GCNs",
)
