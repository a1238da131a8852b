# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/diffusion_bandai.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/diffusion_bandai_s0 --seed 0
# python experiments/diffusion_steps.py ~/jaxmotion-runs/diffusion_bandai_s0   (the accuracy-vs-sampling-steps curve)
#
# The DCT-space diffusion predictor (HumanMAC class) on Bandai-Namco-2 under protocol §4 (docs/pages/protocol.md#datasets) (D = 60,
# 15 -> 60 frames at 30 fps, 1,609 test windows), sized for a 2-core CPU: 15 DCT coefficients of the
# 75-frame window, a 4-block transformer of width 64 (291,580 weights; the release: 8 blocks of 512),
# 6,000 Adam steps x 64 windows (lr 3e-4, constant for half, then linear to 0), EMA 0.995 after 500
# steps, condition dropped for 20% of training windows, no dropout (the release's 0.2 is for ~400k
# steps; here it slowed the loss on the synthetic data); DDIM with DCT completion at 25 steps.
# Runtime (seed 0, 2-core AMD EPYC, under the lock): 275 s in all (training 101 s at 59 steps/s, evaluation
# of the diffusion predictor 149 s). Result (all 1,609 test windows, K = 50, metres; experiments/results/
# diffusion_bandai_metrics.json): diffusion APD 10.532, ADE 0.6349, FDE 0.5657, MMADE 0.6427, MMFDE 0.5708,
# CMD 45.76, FID 2.162, against zero-velocity ADE 0.4328, FDE 0.4844: at this budget the model is worse
# than holding the last pose, its samples mostly broken bodies (ADE-m 1.06). The loss had not flattened
# (0.78 at step 50, 0.077 at 2,450, 0.032 at 5,450 on a decaying lr); the 15-coefficient DCT itself
# costs 0.023 m of ADE on the true futures, so the error is the denoiser's (experiments/results/diffusion.md).
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig


def get_config() -> Config:
    return Config(
        name="diffusion_bandai",
        method="diffusion",
        dataset="../shared/data/bandai-namco-2",
        method_config=DiffusionConfig(dropout=0.0),
        eval_k=(50,),
        ckpt_every=500,
    )
