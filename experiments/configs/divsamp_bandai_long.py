# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/divsamp_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/divsamp_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/divsamp_s0
#
# DivSamp on Bandai-Namco-2 at the long budget: 10x the shared budget of divsamp_bandai.py
# (CVAE 20,000 steps x 64, sampler 4,000 steps x 16), the authors' released Human3.6M loss weights as there; everything else as divsamp_bandai.py. Learning curves every 500 steps
# (K = 50, 200 fixed test windows) in each stage's log.jsonl; experiments/plot_curves.py draws them.
# Measured 2026-12-02, seed 0, 2-core Intel Xeon: 9,439 s for the whole run (an upper bound: the cores were shared
# at times). K = 50, 1,609 windows: DivSamp APD 1.997 ADE 0.1521 FDE 0.1718 MMADE 0.2666; its CVAE 1.336 / 0.1519;
# less diverse than DLow at the long budget (APD 2.874): the CVAE's KL stayed at 1.4-1.7 nats (experiments/results/divsamp.md).
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig


def get_config() -> Config:
    return Config(
        name="divsamp_bandai_long",
        method="divsamp",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50, 5),  # K = 50 and K = 5 tables (DLow and MOJO train a Q network per K)
        ckpt_every=500,
        curve_every=500,
        method_config=DivSampConfig(
            cvae_num_steps=20000, cvae_batch_size=64, cvae_lr_fix_fraction=0.2,
            num_steps=4000, batch_size=16, nk=50, lr_fix_fraction=0.2,
            beta=0.5, lambda_kl=0.5, lambda_acc=40.0, lambda_div=20.0, eta=25.0, tau=1.0,
        ),
    )
