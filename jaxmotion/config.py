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
class CVAEConfig:
    """DLow's CVAE stage (`h36m_nsamp50.yml`: nz 128, beta 0.1, lambda_v 1000, lr 1e-3, batch 64)."""

    nz: int = 128
    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (300, 200)
    lr: float = 1e-3
    batch_size: int = 64
    num_steps: int = 2000
    lr_fix_fraction: float = 0.2  # DLow keeps lr constant for 100 of 500 epochs, then decays linearly to 0
    beta: float = 0.1
    lambda_v: float = 1000.0


@dataclasses.dataclass
class DLowConfig:
    """DLow's Q-network stage (`h36m_nsamp50.yml`: d_scale 100, lambda_j 25, lambda_recon 2, lr 1e-4)."""

    nh_rnn: int = 128
    nh_mlp: tuple[int, ...] = (1024, 512)
    lr: float = 1e-4
    batch_size: int = 32
    num_steps: int = 1000
    lr_fix_fraction: float = 0.2
    d_scale: float = 100.0
    lambda_j: float = 25.0
    lambda_recon: float = 2.0
    lambda_kl: float = 1.0


@dataclasses.dataclass
class Config:
    """Everything `jaxmotion run/train/eval/sample` needs; defaults are the built-in synthetic job."""

    name: str = "dlow_synthetic"
    method: str = "dlow"  # a key of jaxmotion.experiment.METHODS
    dataset: str = "synthetic"  # "synthetic", or a path: BVH folder, Bandai-Namco-2 folder, H36M/HumanEva npz
    data_options: dict = dataclasses.field(default_factory=dict)  # loader options, e.g. {"markers": "bandai"}
    seed: int = 0
    # The built-in job must finish in 10 minutes on 2 CPU cores, so it trains ~2k CVAE steps
    # where DLow trains ~39k. At that budget beta = 0.1 leaves the informative latent dimensions
    # with tiny posterior variances, and latents near the prior decode to broken bodies (on the
    # synthetic data: CVAE ADE-m 0.79 m with beta 0.1 vs 0.36 m with beta 1; DLow's Q network then
    # finds exactly those latents). beta = 1 keeps prior samples on the decoder's training
    # distribution. The Q network's lr is raised from 1e-4 for the same reason (250 vs ~15k steps).
    cvae: CVAEConfig = dataclasses.field(default_factory=lambda: CVAEConfig(num_steps=2000, beta=1.0))
    dlow: DLowConfig = dataclasses.field(default_factory=lambda: DLowConfig(num_steps=250, batch_size=16, lr=5e-4))
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
    mm_deviation: str | None = None  # None (protocol), "divsamp" or "comusion"
    # Method-specific settings of methods other than DLow (their config dataclasses live beside
    # their models); None when unused.
    mojo: Any = None
    divsamp: Any = None


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
    """Returns the config as a JSON-serialisable dict."""
    return dataclasses.asdict(cfg)
