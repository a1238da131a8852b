# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/mojo_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/mojo_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/mojo_s0
#
# MOJO on Bandai-Namco-2 at the long budget: 10x the shared budget of mojo_bandai.py
# (CVAE 20,000 steps x 64, per-band DLow 4,000 steps x 16), the release's loss weights as there; everything else as mojo_bandai.py. Learning curves every 500 steps
# (K = 50, 200 fixed test windows) in each stage's log.jsonl; experiments/plot_curves.py draws them.
# Runtime (seed 0, 2026-12-02, 2-core Intel Xeon, nothing else heavy running): CVAE 2,873 s, per-band DLow
# 1,795 s (learning-curve evaluations included), 4,792 s in all. Result (all 1,609 test windows, K = 50):
# MOJO APD 5.122, ADE 0.1417, FDE 0.1445, MMADE 0.2435, MMFDE 0.1829, BDF 0.154 m, 20.2% of frames outside an
# angle bound; its CVAE from N(0, I) APD 2.424, ADE 0.1876 (experiments/results/mojo.md).
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_bandai_long",
        method="mojo",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50, 5),  # K = 50 and K = 5 tables (DLow and MOJO train a Q network per K)
        ckpt_every=500,
        curve_every=500,
        method_config=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=20000, batch_size=64, q_num_steps=4000, q_batch_size=16, q_lr=5e-4,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
