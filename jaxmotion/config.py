"""Experiment configuration: plain dataclasses, written in Python files under `experiments/configs/`.

A config file defines `get_config() -> Config`; its top comment is the command that runs it, the
runtime and the result it gave.
"""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path
from typing import Any


@dataclasses.dataclass
class Config:
    """Everything `jaxmotion run/train/eval/sample` needs; defaults are the built-in synthetic job."""

    name: str = "dlow_synthetic"
    method: str = "dlow"  # a registered method (`jaxmotion methods` lists them)
    dataset: str = "synthetic"  # "synthetic", or a path: BVH folder, Bandai-Namco-2 folder, H36M/HumanEva npz
    data_options: dict = dataclasses.field(default_factory=dict)  # loader options, e.g. {"markers": "bandai"}
    seed: int = 0
    # The method's own settings, an instance of its `Method.config_type` (DLowConfig, MojoConfig,
    # DivSampConfig, ...); None means that type's defaults (for DLow: the built-in synthetic job,
    # `jaxmotion.models.dlow.DLowConfig()`, whose comments give the budget's reasons).
    method_config: Any = None
    # One Q network is trained per K: DLow's K affine maps are a trained constant.
    eval_k: tuple[int, ...] = (50, 5)
    # Synthetic mode recall (jaxmotion.metrics.mode_recall) on test windows whose decision point is
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
    # Training windows: "windows" (each valid window equally likely) or "sequences" (DLow's release:
    # a sequence uniformly, then a start). Every measured table used "windows".
    train_sampler: str = "windows"
    mm_deviation: str | None = None  # None (protocol), "divsamp" or "comusion"


def load_config(path: str | Path | None) -> Config:
    """Returns the `Config` of a config file (its `get_config()`), or the default when `path` is None."""
    if path is None:
        return Config()
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"config file not found: {path}")
    spec = importlib.util.spec_from_file_location(f"jaxmotion_config_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if not hasattr(module, "get_config"):
        raise ValueError(f"{path}: a config file must define get_config() -> jaxmotion.config.Config")
    cfg = module.get_config()
    if not isinstance(cfg, Config):
        raise TypeError(f"{path}: get_config() returned {type(cfg).__name__}, expected jaxmotion.config.Config")
    return cfg


def to_dict(cfg: Config) -> dict:
    """Returns the config as a JSON-serialisable dict (`method_config_type` names the settings' type)."""
    d = dataclasses.asdict(cfg)
    mc = cfg.method_config
    d["method_config_type"] = None if mc is None else f"{type(mc).__module__}.{type(mc).__name__}"
    return d
