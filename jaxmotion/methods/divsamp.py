"""DivSamp as a method: the GCN CVAE, then the Gumbel-Softmax sampler on the frozen decoder (DivSamp Alg. 1-2).

Settings: `Config.method_config`, a `jaxmotion.models.divsamp.DivSampConfig`. Stages: `cvae`, then
`sampler` (K = `DivSampConfig.nk` in training; any K at test time); with the release's CVAE angle term
(`cvae_lambda_angle > 0`) a computed `angle_bounds` stage comes first, as GSPS's.

BatchNorm statistics: each stage's parameters are the full Flax variable dict `{"params": ...,
"batch_stats": ...}`, so checkpoints and resume carry the running averages with the weights. The
optimiser only touches `"params"` (`loop.bn_optimizer`), and the train step writes the statistics
returned by the loss. In the sampler stage the CVAE's variables are the frozen input and the
decoder runs in evaluation mode (running averages), as the release's `model_t1.eval()`.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import optax

from jaxmotion.method import Method, Stage
from jaxmotion.methods.common import adam, execution_of, window_batches, zero_velocity
from jaxmotion.methods.gsps import bounds_frames
from jaxmotion.models import divsamp, gsps
from jaxmotion.models.divsamp import DivSampConfig
from jaxmotion.nn.execution import Execution
from jaxmotion.train.loop import bn_optimizer, lr_schedule


def settings(cfg) -> DivSampConfig:
    """Returns `cfg.method_config` (the defaults when it is None); `DivSampConfig` checks itself when made."""
    return METHOD.settings(cfg)


def _dummy_nodes(ds, d: DivSampConfig):
    return jnp.zeros((2, ds.dim // 3, 3 * d.n_dct), jnp.float32)


def angle_bounds_stage(prep, d: DivSampConfig) -> Stage:
    """Returns the computed `angle_bounds` stage (GSPS's, `DivSampConfig.cvae_lambda_angle > 0` only): the cosine
    bounds measured on the training poses, checkpointed so that the CVAE and a resumed run use the same numbers."""
    ds = prep.dataset
    roles = gsps.angle_roles(tuple(ds.skeleton.names), tuple(int(p) for p in ds.skeleton.parents))
    return Stage(
        name="angle_bounds",
        init=lambda key, _frozen: {"bounds": jnp.asarray(gsps.measure_angle_bounds(
            bounds_frames(prep.sampler.frames, d.angle_bounds_frames), roles, d.angle_percentile, d.angle_margin))},
        optimizer=optax.set_to_zero(), loss=None, batches=None, num_steps=0,
    )


def cvae_batches(prep, d: DivSampConfig):
    """Returns `rng -> (b, t_total, D)` CVAE training windows: drawn windows, or with `cvae_pseudo_prob > 0` the
    release's expanded set (a window with pseudo multimodal futures takes one of them with that probability)."""
    ds = prep.dataset
    if d.cvae_pseudo_prob == 0:
        return window_batches(prep, d.cvae_batch_size)
    pool = gsps.candidate_pool(prep.sampler.frames, ds.t_his, ds.t_pred, d.mm_candidate_stride)

    def batches(rng):
        w = prep.sampler.sample(rng, d.cvae_batch_size)
        mm, mask = gsps.pseudo_futures(w, pool, rng, t_his=ds.t_his, his_threshold=d.mm_his_threshold,
                                       pred_threshold=d.mm_pred_threshold, num=1)
        swap = mask[:, 0] & (rng.uniform(size=len(w)) < d.cvae_pseudo_prob)
        w[swap, ds.t_his:] = mm[swap, 0]
        return w

    return batches


def cvae_stage(cfg, prep, d: DivSampConfig) -> Stage:
    """Returns the CVAE stage (the release's `run_cvae.py` objective, grad-norm clipping, BatchNorm)."""
    ds = prep.dataset
    model = divsamp.cvae_from_config(d, execution_of(cfg))
    cx = _dummy_nodes(ds, d)
    angle = d.cvae_lambda_angle > 0
    roles = gsps.angle_roles(tuple(ds.skeleton.names), tuple(int(p) for p in ds.skeleton.parents)) if angle else None
    loss = functools.partial(
        divsamp.cvae_loss, model, t_his=ds.t_his, parents=tuple(ds.skeleton.parents), beta=d.beta,
        lambda_v=d.lambda_v, lambda_his=d.lambda_his, lambda_limb=d.lambda_limb, lambda_angle=d.cvae_lambda_angle,
        roles=roles,
    )
    inner = optax.chain(
        optax.clip_by_global_norm(d.cvae_grad_clip),
        optax.adam(lr_schedule(d.cvae_lr, d.cvae_num_steps, d.cvae_lr_fix_fraction)),
    )
    return Stage(
        name="cvae",
        init=lambda key, _frozen: dict(model.init(key, cx, cx, jax.random.key(0), train=False)),
        optimizer=bn_optimizer(inner),
        loss=lambda v, frozen, batch, key: loss(v, batch, key, angle_bounds=frozen["angle_bounds"]["bounds"] if angle else None),
        batches=cvae_batches(prep, d),
        num_steps=d.cvae_num_steps, init_seed=cfg.seed, data_seed=cfg.seed, batch_norm=True,
        frozen=("angle_bounds",) if angle else (),
    )


def sampler_stage(cfg, prep, d: DivSampConfig, name: str = "sampler") -> Stage:
    """Returns the sampler stage on the frozen CVAE (Eq. (13)-(15)); `name` and `d` let an ablation train variants beside it."""
    ds = prep.dataset
    model, cvae = divsamp.sampler_from_config(d, execution_of(cfg)), divsamp.cvae_from_config(d, execution_of(cfg))
    loss = functools.partial(
        divsamp.sampler_loss, model, cvae=cvae, t_his=ds.t_his, k=d.nk, lambda_kl=d.lambda_kl,
        lambda_acc=d.lambda_acc, lambda_div=d.lambda_div, eta=d.eta, diversity=d.diversity, d_scale=d.d_scale,
    )
    return Stage(
        name=name,
        init=lambda key, _frozen: dict(model.init(key, _dummy_nodes(ds, d), jax.random.key(0), 2, train=False)),
        optimizer=bn_optimizer(adam(d.lr, d.num_steps, d.lr_fix_fraction)),
        loss=lambda v, frozen, batch, key: loss(v, cvae_variables=frozen["cvae"], batch=batch, key=key),
        batches=window_batches(prep, d.batch_size),
        num_steps=d.num_steps, init_seed=cfg.seed + 1, data_seed=cfg.seed + 1, frozen=("cvae",), batch_norm=True,
    )


def stages(cfg, prep) -> list[Stage]:
    """Returns DivSamp's stages: the CVAE, then the sampler (after `angle_bounds` when the CVAE has the angle term)."""
    d = settings(cfg)
    first = [angle_bounds_stage(prep, d)] if d.cvae_lambda_angle > 0 else []
    return first + [cvae_stage(cfg, prep, d), sampler_stage(cfg, prep, d)]


def make_predictors(d: DivSampConfig, ds, cvae_variables, sampler_variables, k: int, execution: Execution = Execution()) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity, the CVAE from N(0, I), DivSamp.

    DivSamp draws any K from the same trained sampler (its K is a call argument, not a constant).
    Without `sampler_variables` (None: the sampler is not trained yet) there is no "divsamp".
    """
    cvae, sampler, t_pred = divsamp.cvae_from_config(d, execution), divsamp.sampler_from_config(d, execution), ds.t_pred
    out = {
        "zero_velocity": zero_velocity(t_pred, k),
        "divsamp_cvae": jax.jit(lambda x, key: divsamp.sample_prior(cvae, cvae_variables, x, key, k, t_pred=t_pred)),
    }
    if sampler_variables is not None:
        out["divsamp"] = jax.jit(
            lambda x, key: divsamp.sample_divsamp(cvae, cvae_variables, sampler, sampler_variables, x, key, k, t_pred=t_pred)
        )
    return out


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns `make_predictors` for the config's trained stages (the CVAE's alone while the sampler is not trained)."""
    return make_predictors(settings(cfg), ds, params["cvae"], params.get("sampler"), k, execution_of(cfg))


METHOD = Method(
    name="divsamp",
    config_type=DivSampConfig,
    stages=stages,
    predictors=predictors,
    description="DivSamp (Dang et al., ACM MM 2022): GCN CVAE on DCT, Gumbel-Softmax sampling from a learned basis",
)
