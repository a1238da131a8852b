# jaxmotion run --config experiments/configs/diffusion_synthetic.py --workdir ~/jaxmotion-runs/diffusion_synthetic
# Not run here yet. The diffusion predictor on the built-in synthetic data (15 -> 60 frames, D = 48) at
# the Bandai config's sizes and budget; mode recall at K = 50, 6 and 5 beside the other methods' rows
# (the K = 6 and 5 protocols of MotionMap's claim). K is free at test time: one trained model serves every K.
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig


def get_config() -> Config:
    return Config(
        name="diffusion_synthetic",
        method="diffusion",
        dataset="synthetic",
        method_config=DiffusionConfig(dropout=0.0),
        eval_k=(50, 6, 5),
        ckpt_every=500,
    )
