"""jaxmotion: stochastic 3D human motion prediction in JAX.

The package's folders are its layers, lowest first: `formats/`, `data/`, `body/`, `nn/` (with
`dct`, `gumbel`, `losses`), `models/` (each paper's equations), `pictures/`, `methods/` (each
method as a value: stages and predictors), `train/` (the one stage runner, the train step,
devices and processes), `eval/` (the protocol: references, metrics, evaluators), `experiment` (a
config's job: data -> train -> evaluate -> report), `tools/` (a trained run as a predictor,
prediction from files, BVH out, the viewer) and `cli`.
"""

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


def load(run_dir, stages=None):
    """Returns the trained run at `run_dir` as a predictor (`jaxmotion.tools.predictor.MotionPredictor`): `predict(x, k, key)`, `methods`.

    `stages` (names) restores only those stages (`jaxmotion.tools.predictor.load`).
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
