# jaxmotion train --config experiments/configs/divsamp_bandai.py --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/divsamp_bandai
# jaxmotion eval  --config experiments/configs/divsamp_bandai.py --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/divsamp_bandai
# Shared Bandai budget (CVAE 2000 steps x 64, sampler 400 steps x 16 with K = 50, DLow-style lr schedule).
# Measured (2 shared CPU cores, under the heavy-run lock): train 12 min 7 s (CVAE 2000 steps ~7 min, sampler
# 400 steps ~5 min), eval 3 min. K = 50 on 1,609 test windows: DivSamp APD 1.801 ADE 0.199 FDE 0.252
# MMADE 0.278 MMFDE 0.288; its CVAE from N(0, I) APD 1.752 ADE 0.199; zero-velocity ADE 0.433.
# Details and the comparison with DLow: the DivSamp section of experiments/README.md.
"""DivSamp on Bandai-Namco-2 (15 -> 60 frames at 30 fps, 20 joints).

Architecture: the paper's (supp. Tables 3-4). Loss weights: Bandai-Namco-2 is not in the paper;
we take the authors' Human3.6M values (beta 0.5, lambda_kl 0.5, lambda_acc 40, lambda_div 20,
eta 25), chosen because the content (walk, run, wave, raise hands) is Human3.6M-like and the
future vector (60 frames x 60 dims) is of the same size as Human3.6M's (100 x 48) to within 25 %.
"""
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig


def get_config() -> Config:
    return Config(
        name="divsamp_bandai",
        method="divsamp",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50,),
        method_config=DivSampConfig(
            cvae_num_steps=2000, cvae_batch_size=64, cvae_lr_fix_fraction=0.2,
            num_steps=400, batch_size=16, nk=50, lr_fix_fraction=0.2,
            beta=0.5, lambda_kl=0.5, lambda_acc=40.0, lambda_div=20.0, eta=25.0, tau=1.0,
        ),
    )
