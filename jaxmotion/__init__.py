"""jaxmotion: stochastic 3D human motion prediction in JAX.

The package's folders are its layers, lowest first: `formats/`, `data/`, `body/`, `nn/` (with
`dct`, `gumbel`, `losses`), `models/` (each paper's equations), `pictures/`, `methods/` (each
method as a value: stages and predictors), `train/` (the one stage runner, the train step,
devices and processes), `eval/` (the protocol: references, metrics, evaluators), `experiment` (a
config's job: data -> train -> evaluate -> report), `tools/` (a trained run as a predictor,
prediction from files, BVH out, the viewer) and `cli`.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from jaxmotion.tools.predictor import MotionPredictor

__version__ = "0.1.0"

# Modules that moved into the layer folders: `jaxmotion.<old>` still resolves, with a DeprecationWarning.
_MOVED = {
    "metrics": "eval.metrics", "action_metrics": "eval.action_metrics", "realism": "eval.realism",
    "validity": "eval.validity", "predictor": "tools.predictor", "predict_file": "tools.predict_file",
    "predict_markers": "tools.predict_markers", "viewer": "tools.viewer", "animate": "pictures.animate",
    "viz": "pictures.viz", "retarget": "tools.retarget", "evaluate_folder": "tools.evaluate_folder",
    "fit_c3d": "tools.fit_c3d", "joint_maps": "tools.joint_maps", "distributed": "train.distributed",
    "hugepages": "train.hugepages", "compile_time": "train.compile_time", "run_lock": "train.run_lock",
}


def load(run_dir: str | os.PathLike, stages: tuple[str, ...] | None = None) -> MotionPredictor:
    """Returns a trained model as a predictor: a run folder, an exported `.msgpack` file or a shipped model's name.

        model = jaxmotion.load("bandai")   # the shipped model
        futures = model.predict(x, k=10)   # (t_his, D) -> (10, t_pred, D)

    Args:
        run_dir: a run folder written by `jaxmotion run` / `jaxmotion train` (its `predictor.json` and
            checkpoints), a file written by `jaxmotion export` (`.msgpack`), or the name of a shipped model
            (`"bandai"`; `jaxmotion.tools.predictor.PRETRAINED` lists them).
        stages: names of the stages to restore, for a run folder only (e.g. a GSPS run's
            `("prior", "angle_bounds")` before its generator is trained); `None` restores every stage.

    Returns:
        A `jaxmotion.tools.predictor.MotionPredictor`: `predict(x, k, key, method)` draws K futures of
            `(t_his, D)` or `(b, t_his, D)` observed frames; `layout` says what the frames are (joints,
            frame rate, `t_his`, `t_pred`), `methods` which predictors the run has.

    Raises:
        FileNotFoundError: `run_dir` is neither a folder, a file nor a shipped model's name.
        jaxmotion.errors.CheckpointError: a requested stage has no checkpoint, or a file is not a model.
    """
    from jaxmotion.tools.predictor import load as _load  # imported on use: `import jaxmotion` stays light

    return _load(run_dir, stages)


def __getattr__(name: str):
    if name in _MOVED:
        import importlib
        import warnings

        warnings.warn(f"jaxmotion.{name} is now jaxmotion.{_MOVED[name]}", DeprecationWarning, stacklevel=2)
        return importlib.import_module(f"jaxmotion.{_MOVED[name]}")
    raise AttributeError(f"module 'jaxmotion' has no attribute {name!r}")
