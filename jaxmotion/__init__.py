"""jaxmotion: stochastic 3D human motion prediction in JAX."""

__version__ = "0.1.0"


def load(run_dir, stages=None):
    """Returns the trained run at `run_dir` as a predictor (`jaxmotion.predictor.MotionPredictor`): `predict(x, k, key)`, `methods`.

    `stages` (names) restores only those stages (`jaxmotion.predictor.load`).
    """
    from jaxmotion.predictor import load as _load  # imported on use: `import jaxmotion` stays light

    return _load(run_dir, stages)
