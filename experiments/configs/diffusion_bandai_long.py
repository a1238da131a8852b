# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/diffusion_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/diffusion_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/diffusion_s0
#
# The diffusion predictor on Bandai-Namco-2 at the long budget: 10x the steps of diffusion_bandai.py
# (60,000 Adam steps x 64 windows), everything else as there, with the release's EMA start (2,000
# steps) and learning curves (K = 50, 200 fixed test windows, every 5,000 steps) in diffusion/log.jsonl.
# Evaluated at K = 50 and K = 5 (one model, any K).
# Result (seed 0, 1,609 windows; experiments/results/long/diffusion_bandai_long_s0_{metrics,curve}.json,
# experiments/results/diffusion_bandai_long_s0_curves.png): K = 50 APD 3.299, ADE 0.2689, FDE 0.2482,
# MMADE 0.3024; K = 5 ADE 0.3214. Better than zero-velocity (ADE 0.4328), less accurate than the long-budget
# CVAE samplers (DLow 0.167, DivSamp 0.155, MOJO 0.142); ADE still fell 2% over the last 12,000 steps.
# Runtime: 2,247 s from start to report on a 2-core AMD EPYC (family 26) shared with a test suite.
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
