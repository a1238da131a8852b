# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/diffusion_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/diffusion_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/diffusion_s0
#
# The diffusion predictor on Bandai-Namco-2 at the long budget: 10x the steps of diffusion_bandai.py
# (60,000 Adam steps x 64 windows), everything else as there, with the release's EMA start (2,000
# steps) and learning curves (K = 50, 200 fixed test windows, every 5,000 steps) in diffusion/log.jsonl.
# Evaluated at K = 50 and K = 5 (one model, any K). Not run yet: about 10x diffusion_bandai.py's training time.
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig


def get_config() -> Config:
    return Config(
        name="diffusion_bandai_long",
        method="diffusion",
        dataset="../shared/data/bandai-namco-2",
        method_config=DiffusionConfig(dropout=0.0, num_steps=60000, ema_start=2000),
        eval_k=(50, 5),
        ckpt_every=2000,
        curve_every=5000,
    )
