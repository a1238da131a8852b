"""A method is a value: its config type, its training stages, its predictors, registered by name.

    from jaxmotion.method import Method, Stage, register

    register(Method(name="mine", config_type=MyConfig, stages=my_stages, predictors=my_predictors))

`jaxmotion train/eval/run` look the config's `method` up in this registry (`jaxmotion.methods.get_method`,
which first registers the built-in methods: the modules of `jaxmotion.methods`, each defining `METHOD`)
and hand its stages to the one stage runner (`jaxmotion.train.runner`), which trains, checkpoints,
resumes and restores every method the same way. A package of your own registers its methods by
calling `register` on import, or through the `jaxmotion.methods` entry-point group (an entry point
that loads a `Method`), or a config file can call `register` before `get_config()` returns.
docs/pages/add-method.md walks through DLow.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np
import optax

# `(x (b, t_his, D), key) -> (b, K, t_pred, D)`, jitted.
Predictor = Callable[[jax.Array, jax.Array], jax.Array]
# `(params, frozen, batch, key) -> (loss, metrics)`; with BatchNorm `(loss, (metrics, new_batch_stats))`.
LossFn = Callable[[Any, Any, Any, jax.Array], tuple]


class ExtraMetrics(NamedTuple):
    """A method's own metrics for one trained run (`Method.extra_metrics`).

    `per_window(pred (n, K, t_pred, D), gt (n, t_pred, D)) -> {name: (n,) array}`; evaluation
    averages each over windows (NaN skipped). `record`: added to every record's `config` (what the
    evaluation used that the config does not hold, e.g. GSPS's measured angle bounds).
    """

    per_window: Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]
    record: dict = {}


@dataclasses.dataclass(frozen=True)
class Stage:
    """One training stage: what it trains, on what, for how long.

    `init(key, frozen)` returns the initial parameters (a model's full variable dict when
    `batch_norm`); `frozen` is a dict `{stage name: trained parameters}` of the earlier stages
    listed in `frozen` (e.g. DLow's Q network sees the CVAE), so a stage may start from them.
    `loss(params, frozen, batch, key)` is the objective. A stage with `num_steps=0` trains nothing:
    its parameters are what `init` computes from the earlier stages (a codebook, statistics, ...),
    checkpointed like any other stage's.
    `batches(rng)` returns one batch (a pytree of numpy arrays) for `np.random.default_rng([data_seed,
    step])`, so a resumed stage sees exactly the batches of an uninterrupted one. The stage's folder
    in the work directory is `name` (checkpoints in `name/ckpt`, log in `name/log.jsonl`).
    """

    name: str
    init: Callable[[jax.Array, dict], Any]
    optimizer: optax.GradientTransformation
    loss: LossFn | None  # None only for a stage with nothing to train (num_steps=0)
    batches: Callable[[np.random.Generator], Any] | None
    num_steps: int
    init_seed: int = 0
    data_seed: int = 0
    frozen: tuple[str, ...] = ()
    batch_norm: bool = False  # params are `{"params", "batch_stats"}`; the loss returns new statistics

    def __post_init__(self):
        if not self.name or "/" in self.name:
            raise ValueError(f"Stage.name must be a non-empty folder name, got {self.name!r}")
        if self.num_steps < 0:
            raise ValueError(f"Stage {self.name!r}: num_steps must be >= 0, got {self.num_steps}")
        if self.num_steps > 0 and (self.loss is None or self.batches is None):
            raise ValueError(f"Stage {self.name!r}: a stage that trains ({self.num_steps} steps) needs a loss and batches")


@dataclasses.dataclass(frozen=True)
class Method:
    """A method: its settings type and how to train and sample it.

    - `config_type`: the type of `Config.method_config` (a dataclass; `config_type()` is the default).
    - `stages(cfg, prep) -> [Stage]`: the training stages in order (`cfg` a `jaxmotion.config.Config`
      whose `method_config` is checked, `prep` an `experiment.Prepared`: dataset, train sampler, test windows).
    - `predictors(cfg, ds, params, k) -> {name: Predictor}`: jitted samplers of K futures, including
      the baselines the method is compared against; `params` is `{stage name: trained parameters}`.
    - `extra_metrics(cfg, ds, params) -> ExtraMetrics`: optional; the method's own per-window
      metrics for the trained stages `params` (MOJO's realism, GSPS's validity under its own angle
      bounds and pose prior, MotionMap's distinct futures), and what their record should say.
    - `part_control(cfg, ds, params, x, key, k, fix) -> (b, K, t_pred, D)`: optional body-part control
      (`jaxmotion sample --fix-part`): K futures in which the parts named in `fix` are held and the
      others vary; it raises a ValueError naming the valid parts. None: the method has no part control.
    - `pictures(cfg, prep, params, workdir, i) -> [Path]`: optional; the method's own pictures of test
      window `i` (`prep` an `experiment.Prepared`), written into `workdir` by `experiment.report`
      (`jaxmotion run`) beside `samples.png`, for the window it draws (MotionMap's maps and modes).
    - `reference_futures`: where the multimodal ground truth of MMADE/MMFDE comes from: "test"
      ([protocol §2][metrics]: the futures of test windows with a similar last observed pose) or "train"
      (the futures of training windows, a pool of pseudo ground truth); "test" is the protocol.
    - `curve_skip`: predictor names left out of the learning curves (constant or slow ones).
    - `deterministic`: predictor names whose K futures are K copies of one (zero-velocity). Evaluation
      scores one copy: every metric is then the same as on the K copies (APD 0; the min and median over
      K of equal terms are that term; MM errors, mode recall and the `extra_metrics`, which are means
      over the K samples, unchanged; FID's feature moments counted K times), at 1/K of the cost.

    `predictors` returns the predictors the stages in `params` allow: during training, learning
    curves call it with the stages trained so far (the current one included, later ones absent),
    and a stage whose only predictors are in `curve_skip` has no curve.
    """

    name: str
    config_type: type
    stages: Callable[[Any, Any], list[Stage]]
    predictors: Callable[[Any, Any, dict, int], dict[str, Predictor]]
    extra_metrics: Callable[[Any, Any, dict], ExtraMetrics] | None = None
    part_control: Callable[..., jax.Array] | None = None
    pictures: Callable[[Any, Any, dict, Path, int], list[Path]] | None = None
    reference_futures: str = "test"
    description: str = ""
    # Predictors left out of the learning curves (`Config.curve_every`): constant or slow baselines.
    curve_skip: tuple[str, ...] = ("zero_velocity",)
    deterministic: tuple[str, ...] = ("zero_velocity",)

    def __post_init__(self):
        if self.reference_futures not in ("test", "train"):
            raise ValueError(f"Method {self.name!r}: reference_futures must be 'test' or 'train', got {self.reference_futures!r}")

    def settings(self, cfg) -> Any:
        """Returns `cfg.method_config` checked against `config_type` (the default `config_type()` when it is None)."""
        mc = cfg.method_config if cfg.method_config is not None else self.config_type()
        if not isinstance(mc, self.config_type):
            raise TypeError(
                f"method {self.name!r} takes Config.method_config of type {self.config_type.__module__}."
                f"{self.config_type.__name__}, got {type(mc).__module__}.{type(mc).__name__}"
            )
        return mc


_REGISTRY: dict[str, Method] = {}


def register(method: Method, *, replace: bool = False) -> Method:
    """Adds `method` to the registry under `method.name` (a second method of the same name needs `replace=True`)."""
    if not isinstance(method, Method):
        raise TypeError(f"register: expected a jaxmotion.method.Method, got {type(method).__name__}")
    old = _REGISTRY.get(method.name)
    if old is not None and old is not method and not replace:
        raise ValueError(f"a method named {method.name!r} is already registered; pass replace=True to replace it")
    _REGISTRY[method.name] = method
    return method


def registered() -> dict[str, Method]:
    """Returns the methods registered so far, by name (`jaxmotion.methods.methods()` also loads the built-in ones)."""
    return dict(sorted(_REGISTRY.items()))
