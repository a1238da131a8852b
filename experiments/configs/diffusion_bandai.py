# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/diffusion_bandai.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/diffusion_bandai_s0 --seed 0
# python experiments/diffusion_steps.py ~/jaxmotion-runs/diffusion_bandai_s0   (the accuracy-vs-sampling-steps curve)
#
# The DCT-space diffusion predictor (HumanMAC class) on Bandai-Namco-2 under PROTOCOL sec. 3 (D = 60,
# 15 -> 60 frames at 30 fps, 1,609 test windows), sized for a 2-core CPU: 15 DCT coefficients of the
# 75-frame window, a 4-block transformer of width 64 (291,580 weights; the release: 8 blocks of 512),
# 6,000 Adam steps x 64 windows (lr 3e-4, constant for half, then linear to 0), EMA 0.995 after 500
# steps, condition dropped for 20% of training windows, no dropout (the release's 0.2 is for ~400k
# steps; here it slowed the loss on the synthetic data); DDIM with DCT completion at 25 steps.
# Runtime and result: RESULT
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
