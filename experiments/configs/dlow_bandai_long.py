# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/dlow_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/dlow_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/dlow_s0
#
# DLow on Bandai-Namco-2 at the long budget: 10x the shared budget of dlow_bandai.py
# (CVAE 20,000 steps x 64, Q network 4,000 steps x 16), the paper's loss weights (beta 0.1,
# d_scale 100, lambda_j 25, lambda_recon 2), everything else as dlow_bandai.py. Learning curves:
# APD/ADE/FDE/MMADE of the CVAE from N(0, I) and of DLow at K = 50 on 200 fixed test windows every
# 500 steps, in each stage's log.jsonl (experiments/plot_curves.py draws them).
# Runtime (seed 0, 2-core AMD EPYC shared with other work, so upper bounds): CVAE 5,153 s, Q 2,014 s of
# training, evaluation ~90 s. Result (all 1,609 test windows, K = 50): DLow APD 2.874, ADE 0.1617,
# FDE 0.1574, MMADE 0.2556, MMFDE 0.1888; its CVAE from N(0, I) APD 2.102, ADE 0.1574; BDF 0.063 m,
# 6.1% of frames outside an angle bound (experiments/results/dlow.md).
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_bandai_long",
        dataset="../shared/data/bandai-namco-2",
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=20000, batch_size=64, beta=0.1),
            # Q lr 5e-4 as dlow_bandai.py (the release's 1e-4 is for ~15.6k steps of batch 32).
            q=QConfig(num_steps=4000, batch_size=16, lr=5e-4),
        ),
        eval_k=(50, 5),  # K = 50 and K = 5 tables (DLow and MOJO train a Q network per K)
        ckpt_every=500,
        curve_every=500,
    )
