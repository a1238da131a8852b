"""Experiment configuration: plain dataclasses, written in Python files under `experiments/configs/`.

A config file defines `get_config() -> Config`; its top comment is the command that runs it, the
runtime and the result it gave. `load_config` checks it (`validate`): unknown fields, wrong types and
impossible values are one `jaxmotion.errors.ConfigError` listing every problem.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import difflib
import importlib.machinery
import importlib.util
import math
import re
import sys
import traceback
import types
import typing
from pathlib import Path
from typing import Any

from jaxmotion.errors import ConfigError
from jaxmotion.nn.execution import BATCH_NORMS, PRECISIONS


@dataclasses.dataclass(slots=True)  # slots: setting a misspelt attribute (`c.ckpt_evry = 7`) is an error, as in every method config
class Config:
    """Everything `jaxmotion run/train/eval/sample` needs; defaults are the built-in synthetic job."""

    name: str = "dlow_synthetic"
    method: str = "dlow"  # a registered method (`jaxmotion methods` lists them)
    dataset: str = "synthetic"  # "synthetic", or a path: BVH folder, Bandai-Namco-2 folder, H36M/HumanEva npz
    data_options: dict = dataclasses.field(default_factory=dict)  # loader options, e.g. {"markers": "bandai"}
    seed: int = 0
    # Which windows evaluation scores: "test" (the protocol's test split) or "val" (one training
    # sequence in five per action held back, `jaxmotion.data.validation`; training uses the rest and
    # the test split is dropped). Settings are chosen on "val", never on "test".
    split: str = "test"
    # The method's own settings, an instance of its `Method.config_type` (DLowConfig, MojoConfig,
    # DivSampConfig, ...); None means that type's defaults (for DLow: the built-in synthetic job,
    # `jaxmotion.models.dlow.DLowConfig()`, whose comments give the budget's reasons).
    method_config: Any = None
    # One Q network is trained per K: DLow's K affine maps are a trained constant.
    eval_k: tuple[int, ...] = (50, 5)
    # Synthetic mode recall (jaxmotion.eval.metrics.mode_recall) on test windows whose decision point is
    # at most `mode_max_boundary` future frames away (there any two modes are >= 0.291 m apart in
    # ADE-term): each sample is assigned to its nearest mode and reaches it when its ADE-term is
    # below `mode_threshold`. 0.4 m is about the zero-velocity ADE on this data (0.42 m): a sample
    # reaches a mode when it follows it at least as closely as standing still follows the truth.
    mode_threshold: float = 0.4
    mode_max_boundary: int = 15
    ckpt_every: int = 500
    log_every: int = 50
    eval_batch: int = 64
    max_test_windows: int | None = None  # None: every protocol window
    # Training windows: "windows" (each valid window equally likely), "sequences" (a sequence
    # uniformly, then a start) or "subjects" (the releases' `sample()`: a subject uniformly, then one
    # of its sequences, then a start; `jaxmotion.data.windows.TrainSampler`). Every measured Bandai
    # table used "windows".
    train_sampler: str = "windows"
    # None (protocol), or the averaging of a published code base: "divsamp", "comusion" or "gsps"
    # (`jaxmotion.eval.protocol.DEVIATIONS`, each described there).
    mm_deviation: str | None = None
    # Where MMADE / MMFDE's multimodal ground truth comes from (protocol §2 (docs/pages/protocol.md#metrics); `jaxmotion.eval.references`):
    # None: the method's own (`Method.reference_futures`: "test" for every method but MotionMap,
    # "train" for it); "test": the protocol (last observed pose within the dataset's threshold, test
    # windows); "train": the same over the training windows (every t_his frames); "motionmap-test" /
    # "motionmap-train": MotionMap's (last three observed frames, candidates motion-transferred onto
    # the window's skeleton, and so are their futures before the metrics; MotionMap Tables 3-4 / 1-2).
    mm_ground_truth: str | None = None
    # Learning curves: every `curve_every` training steps (0: never) each stage evaluates APD, ADE,
    # FDE, MMADE and MMFDE of the predictors its parameters so far allow, at K = `curve_k`, on
    # `curve_windows` evenly spaced test windows (their MM sets over every test window), into its
    # log.jsonl (lines with "curve": true); `experiments/plot_curves.py` draws them.
    curve_every: int = 0
    curve_windows: int = 200
    curve_k: int = 50
    # CMD and FID (`jaxmotion.eval.action_metrics`, protocol §2 (docs/pages/protocol.md#metrics)) in every record's metrics when the
    # dataset has action labels (Bandai-Namco-2, the synthetic data); absent otherwise. FID's action
    # classifier is the project's own (not BeLFusion's Human3.6M one), trained once per dataset for
    # `action_classifier_steps` Adam steps and cached under `~/.cache/jaxmotion/action_classifiers/`.
    action_metrics: bool = True
    action_classifier_steps: int = 1000
    # The networks' weight products (jaxmotion/nn/precision.py): "float32" (default), or "bf16":
    # bfloat16 operands with float32 accumulation, everything else float32. Faster only on a CPU with
    # bfloat16 instructions (or a GPU / TPU); its effect on speed and on the metrics is measured in
    # benchmarks/results/bf16.md. GSPS's flow prior, MotionMap and the metrics keep float32 always.
    precision: str = "float32"
    # BatchNorm's training moments on several devices (DivSamp; jaxmotion/nn/execution.py `Execution.batch_norm`):
    # "global" (default, exact: any device count gives one device's numbers) or "per_device" (each device's
    # rows, as PyTorch DistributedDataParallel without SyncBatchNorm: no collective per layer, other numbers).
    batch_norm: str = "global"
    # Gradient accumulation: each device takes its share of every batch in `micro_batches` equal
    # micro-batches, one after another, and the optimiser steps once on their mean gradient (one
    # all-reduce per step): a global batch too large for the devices' memory. Equal to the whole batch
    # at once for losses that are means over windows (DLow, MOJO, MotionMap); with BatchNorm (DivSamp,
    # GSPS) each micro-batch is normalised by its own moments. Batch sizes must be multiples of the
    # device count times `micro_batches`.
    micro_batches: int = 1


def load_config(path: str | Path | None) -> Config:
    """Returns the `Config` of a config file (its `get_config()`), or the default when `path` is None."""
    if path is None:
        return Config()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"config file not found: {path}")
    # A loader named explicitly: any file name is read as Python (`spec_from_file_location` knows only `.py`).
    name = f"jaxmotion_config_{path.stem}"
    spec = importlib.util.spec_from_loader(name, importlib.machinery.SourceFileLoader(name, str(path)))
    module = importlib.util.module_from_spec(spec)
    with _config_code(path, vars(module)):
        spec.loader.exec_module(module)
    if not callable(getattr(module, "get_config", None)):
        raise ConfigError(str(path), ["a config file must define get_config() -> jaxmotion.config.Config"])
    # A dataclass rejects only the first unknown keyword; read the file to list them all.
    unknown = _unknown_fields(path, vars(module))
    if unknown:
        raise ConfigError(str(path), unknown)
    with _config_code(path, vars(module)):
        cfg = module.get_config()
    if not isinstance(cfg, Config):
        raise ConfigError(str(path), [f"get_config() returned a {type(cfg).__name__}, expected a jaxmotion.config.Config"])
    validate(cfg, source=str(path))
    return cfg


def budget_fraction(path: str | Path, fraction: float, **changes) -> Config:
    """Returns the config file `path`'s config with its method's `num_steps` scaled by `fraction` and `changes` set.

    A budget-reduced copy of a release config: the steps rounded to the nearest integer (at least 1); schedules
    the method states as fractions of the run (learning-rate milestones, the constant stretch before a linear
    decay) scale with it, and stages with their own step counts (a GSPS prior, a DLow CVAE) keep theirs. Example,
    a config file holding a tenth of GSPS's generator budget:

        def get_config():
            return budget_fraction(Path(__file__).with_name("gsps_humaneva.py"), 0.1, name="gsps_humaneva_10pct")
    """
    if not 0 < fraction <= 1:
        raise ConfigError(str(path), [f"budget_fraction: fraction must be in (0, 1], got {fraction}"])
    base = load_config(path)
    steps = max(1, round(base.method_config.num_steps * fraction))
    return dataclasses.replace(base, method_config=dataclasses.replace(base.method_config, num_steps=steps), **changes)


@contextlib.contextmanager
def _config_code(path: Path, namespace: dict):
    """Turns an exception raised by the config file's own code into a `ConfigError` naming its line.

    A misspelt attribute (`c.ckpt_evry = 7`) is an AttributeError, since the config dataclasses have
    slots; the nearest field is suggested.
    """
    try:
        yield
    except ConfigError:
        raise
    except SyntaxError as e:
        raise ConfigError(str(path), [f"line {e.lineno}: {e.msg}"]) from None
    except Exception as e:
        tb = traceback.extract_tb(e.__traceback__)
        line = next((f.lineno for f in reversed(tb) if Path(f.filename).resolve() == path.resolve()), None)
        where = f"line {line}: " if line is not None else ""
        problem = f"{where}{type(e).__name__}: {e}"
        m = re.fullmatch(r"'(\w+)' object has no attribute '(\w+)'", str(e)) if isinstance(e, AttributeError) else None
        cls = m and _config_types(namespace).get(m[1])
        if cls is not None:
            names = [f.name for f in dataclasses.fields(cls)]
            near = difflib.get_close_matches(m[2], names, n=1)
            problem = f"{where}unknown field {m[2]!r} of {m[1]}" + (f"; did you mean {near[0]!r}?" if near else f"; fields: {names}")
        raise ConfigError(str(path), [problem]) from None


def _config_types(namespace: dict) -> dict[str, type]:
    """Returns the config dataclasses by name: `Config`, those of every jaxmotion module imported so far (the
    methods' settings: a config file imports the model modules it names), the file's own, and their nested ones."""
    loaded = [m for name, m in list(sys.modules.items()) if name.startswith("jaxmotion.") and m is not None]
    modules = loaded + [v for v in namespace.values() if isinstance(v, types.ModuleType)]
    todo = [Config, *(v for m in modules for v in vars(m).values() if isinstance(v, type)),
            *(v for v in namespace.values() if isinstance(v, type))]
    found: dict[str, type] = {}
    while todo:
        t = todo.pop()
        if not (isinstance(t, type) and dataclasses.is_dataclass(t)) or t.__name__ in found:
            continue
        found[t.__name__] = t
        with contextlib.suppress(Exception):
            todo += typing.get_type_hints(t).values()
    return found


def _unknown_fields(path: Path, namespace: dict) -> list[str]:
    """Returns a problem per keyword of a dataclass call in the file (`Config(...)`, `DLowConfig(...)`) that is no field."""
    problems = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        target = namespace.get(f.id) if isinstance(f, ast.Name) else None
        if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in namespace:
            target = getattr(namespace[f.value.id], f.attr, None)
        if not (isinstance(target, type) and dataclasses.is_dataclass(target)):
            continue
        names = [fl.name for fl in dataclasses.fields(target) if fl.init]
        for kw in node.keywords:
            if kw.arg is not None and kw.arg not in names:
                near = difflib.get_close_matches(kw.arg, names, n=1)
                hint = f"; did you mean {near[0]!r}?" if near else f"; fields: {names}"
                problems.append(f"line {node.lineno}: unknown field {kw.arg!r} of {target.__name__}{hint}")
    return problems


SEED_LIMIT = 2**32  # jax.random.key keeps a seed's low 32 bits: 2**32 would be seed 0 again

_CHOICES = {"split": ("test", "val"), "train_sampler": ("windows", "sequences", "subjects"), "mm_deviation": (None, "divsamp", "comusion", "gsps"),
            "mm_ground_truth": (None, "test", "train", "motionmap-test", "motionmap-train"),
            "precision": PRECISIONS, "batch_norm": BATCH_NORMS}
# `Config`'s intervals: (field, rule, what the rule asks), checked once the field's type is right.
_CONFIG_RULES = (
    *((n, lambda v: v >= 1, ">= 1") for n in ("ckpt_every", "log_every", "eval_batch", "micro_batches")),
    ("eval_k", lambda v: bool(v) and all(k >= 1 for k in v), ">= 1 each"),
    ("eval_k", lambda v: len(set(v)) == len(v), "distinct values (each K is one evaluation record)"),
    ("seed", lambda v: 0 <= v < SEED_LIMIT, "in [0, 2**32) (a jax key keeps 32 bits of it)"),
    ("max_test_windows", lambda v: v is None or v >= 1, "None or >= 1"),
    ("mode_threshold", lambda v: v > 0, "> 0"),
    ("mode_max_boundary", lambda v: v >= 0, ">= 0"),
    ("curve_every", lambda v: v >= 0, ">= 0 (0: no learning curve)"),
    *((n, lambda v: v >= 1, ">= 1") for n in ("curve_windows", "curve_k")),
    ("action_classifier_steps", lambda v: v >= 1, ">= 1"),
)


def validate(cfg: Config, num_train_windows: int | None = None, source: str = "config") -> None:
    """Raises `ConfigError` listing every wrong type and impossible value of `cfg` and its `method_config`.

    Types are checked against the dataclass annotations; values by field name: steps >= 0, batch
    sizes >= 1 (and at most `num_train_windows` when given), learning rates > 0, fractions in [0, 1],
    every K >= 1, every float finite, and `Config`'s own choices and intervals.
    """
    problems = _check_dataclass(cfg, "")
    bad = {p.split(" ", 1)[0] for p in problems}  # fields of the wrong type: their values are not checked too
    for name, rule, text in _CONFIG_RULES:
        if name not in bad and not rule(getattr(cfg, name)):
            problems.append(f"{name} must be {text}, got {getattr(cfg, name)!r}")
    for name, choices in _CHOICES.items():
        if getattr(cfg, name) not in choices:
            problems.append(f"{name} must be one of {choices}, got {getattr(cfg, name)!r}")
    if cfg.method_config is not None and dataclasses.is_dataclass(cfg.method_config):
        problems += _check_dataclass(cfg.method_config, "method_config.", num_train_windows)
    if problems:
        raise ConfigError(source, problems)


# Fields of a method's settings that are layer widths or counts of units: each (or each entry of a tuple) >= 1.
WIDTH_FIELDS = re.compile(r"(^|_)(nz|nh(_[a-z]+)?|hidden|latent|ff|features|base_dim|num_bases|n_dct|num_heads|hm_size|hm_channels)$")


def memory_estimate(cfg: Config, dim: int, t_his: int, t_pred: int) -> dict[str, float]:
    """Returns bytes of the largest single allocations the config asks for on data of frame size `dim`, by what.

    Lower bounds from the settings alone, not a profile: evaluation holds a batch of futures
    (eval_batch x K x t_pred x D) and APD's pairwise distances (eval_batch x K x K); training, per
    settings section (a stage), the widest layer's recurrent weights with their gradient and Adam's two
    moments (4 x 3 x W x max(W, D)), and one batch's activations at that width (batch x K x
    (t_his + t_pred) x 3 W). float32 throughout.
    """
    k = max(cfg.eval_k)
    out = {
        f"evaluation: eval_batch {cfg.eval_batch} x K {k} futures of {t_pred} frames x {dim}": cfg.eval_batch * k * t_pred * dim * 4.0,
        f"evaluation: APD's eval_batch {cfg.eval_batch} x K {k} x K {k} distances": cfg.eval_batch * k * k * 4.0,
    }
    sections = [cfg.method_config] if dataclasses.is_dataclass(cfg.method_config) else []
    for obj in sections:  # each settings dataclass (a stage's section) on its own: its batch meets its widths
        ints: dict[str, list[int]] = {}
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if dataclasses.is_dataclass(v) and not isinstance(v, type):
                sections.append(v)
            elif isinstance(v, int) and not isinstance(v, bool):
                ints.setdefault(f.name, []).append(v)
            elif isinstance(v, tuple) and all(isinstance(w, int) for w in v):
                ints.setdefault(f.name, []).extend(v)
        width = max((w for n, ws in ints.items() if WIDTH_FIELDS.search(n) for w in ws), default=0)
        batch = max((b for n, bs in ints.items() if n.endswith("batch_size") for b in bs), default=0)
        nk = max((x for n, xs in ints.items() if n in ("nk", "k", "num_k") for x in xs), default=1)
        if width:
            where = f"training ({type(obj).__name__})"
            out[f"{where}: the widest layer's weights ({width}) with gradient and Adam's moments"] = 4 * 3 * width * max(width, dim) * 4.0
            out[f"{where}: a batch of {batch} x {nk} samples x {t_his + t_pred} frames at width {width}"] = batch * nk * (t_his + t_pred) * 3 * width * 4.0
    return out


def memory_limit() -> tuple[float, str]:
    """Returns the bytes one allocation may take here and where: the first device's memory, else the host's RAM."""
    import os

    try:
        import jax

        dev = jax.devices()[0]
        stats = dev.memory_stats() or {}
        if stats.get("bytes_limit"):
            return float(stats["bytes_limit"]), f"{dev.device_kind}'s memory"
    except Exception:  # no backend yet: the host's memory is the bound
        pass
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")), "this machine's RAM"


def check_memory(cfg: Config, dim: int, t_his: int, t_pred: int, source: str = "config") -> None:
    """Raises `ConfigError` naming the largest allocation of `memory_estimate` when it exceeds `memory_limit` (before a step is trained)."""
    limit, where = memory_limit()
    what, b = max(memory_estimate(cfg, dim, t_his, t_pred).items(), key=lambda item: item[1])
    if b > limit:  # the largest one: one line
        raise ConfigError(source, [f"{what} need about {b / 2**30:,.0f} GiB at once, more than {where} ({limit / 2**30:.0f} GiB); lower it"])


def _check_dataclass(obj, prefix: str, num_windows: int | None = None) -> list[str]:
    problems = []
    try:
        hints = typing.get_type_hints(type(obj))
    except Exception:  # an annotation that does not resolve: check the values only
        hints = {}
    for f in dataclasses.fields(obj):
        name, v = prefix + f.name, getattr(obj, f.name)
        hint = hints.get(f.name, Any)
        if not _type_ok(v, hint):
            problems.append(f"{name} must be {_type_name(hint)}, got {type(v).__name__} {v!r}")
            continue
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            if prefix:  # `Config.method_config` itself is checked by `validate`
                problems += _check_dataclass(v, name + ".", num_windows)
        elif prefix and isinstance(v, tuple) and WIDTH_FIELDS.search(f.name):
            if any(isinstance(w, int) and w < 1 for w in v):
                problems.append(f"{name} (layer widths) must be >= 1 each, got {v}")
        elif prefix and not isinstance(v, bool):  # the method's settings: rules by field name
            problems += _check_value(name, f.name, v, num_windows)
    return problems


_FRAME_BATCHES = {"prior_batch_size"}


def _check_value(name: str, field: str, v, num_windows: int | None) -> list[str]:
    if isinstance(v, float) and not math.isfinite(v):
        return [f"{name} must be finite, got {v}"]
    if not isinstance(v, (int, float)):
        return []
    if field.endswith("num_steps") and v < 0:
        return [f"{name} must be >= 0, got {v}"]
    if field.endswith("batch_size"):
        if v < 1:
            return [f"{name} must be >= 1, got {v}"]
        # GSPS's pose prior draws single training frames with replacement, so its batch may pass the window count.
        if num_windows is not None and v > num_windows and field not in _FRAME_BATCHES:
            return [f"{name} {v} is larger than the {num_windows} training windows"]
    if (field == "lr" or field.endswith("_lr")) and not v > 0:
        return [f"{name} must be > 0, got {v}"]
    if field.endswith("fraction") and not 0 <= v <= 1:
        return [f"{name} must be in [0, 1], got {v}"]
    if field in ("k", "nk", "num_k") and v < 1:
        return [f"{name} (K) must be >= 1, got {v}"]
    if WIDTH_FIELDS.search(field) and v < 1:
        return [f"{name} (a layer width) must be >= 1, got {v}"]
    return []


def _type_ok(v, hint) -> bool:
    if hint is Any:
        return True
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_type_ok(v, a) for a in args)
    if hint is type(None):
        return v is None
    if hint is bool:
        return isinstance(v, bool)
    if hint is int:
        return isinstance(v, int) and not isinstance(v, bool)
    if hint is float:
        return isinstance(v, (int, float)) and not isinstance(v, bool)
    if origin is tuple:
        if not isinstance(v, tuple):
            return False
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_type_ok(x, args[0]) for x in v)
        return not args or (len(args) == len(v) and all(_type_ok(x, a) for x, a in zip(v, args)))
    if origin is not None:
        return isinstance(v, origin)
    return isinstance(v, hint) if isinstance(hint, type) else True


def _type_name(hint) -> str:
    return hint.__name__ if isinstance(hint, type) else str(hint).replace("typing.", "")


def to_dict(cfg: Config) -> dict:
    """Returns the config as a JSON-serialisable dict (`method_config_type` names the settings' type)."""
    d = dataclasses.asdict(cfg)
    mc = cfg.method_config
    d["method_config_type"] = None if mc is None else f"{type(mc).__module__}.{type(mc).__name__}"
    return d
