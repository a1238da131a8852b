# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/mojo_dct_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/mojo_dct_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/mojo_dct_s0
#
# MOJO-DCT (MOJO without the latent DCT space: one 128-d latent vector, plain KLD weight 0.1, the
# release's `amass_vanilla_nsamp50.yml`) on Bandai-Namco-2 at the long budget: 10x the shared
# budget of mojo_dct_bandai.py (CVAE 20,000 steps x 64, DLow 4,000 steps x 16), everything else as
# there, so that it pairs with mojo_bandai_long.py for MOJO's claim "the latent DCT space is more diverse
# than a vector latent". Learning curves every 500 steps (K = 50, 200 fixed test windows).
# Runtime and result (seed 0, 2026-12-02, 2-core Intel Xeon): 91 min; K = 50 APD 0.260 (its CVAE 0.360), ADE 0.170:
# the vector latent collapses (KL ~0.001 nats from step 2,000). experiments/results/mojo.md.
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_dct_bandai_long",
        method="mojo",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50, 5),  # K = 50 and K = 5 tables (DLow and MOJO train a Q network per K)
        ckpt_every=500,
        curve_every=500,
        method_config=MojoConfig(
            variant="MOJO-DCT", latent="vector", nz=128, residual=True, loss="mojo", alpha=3.0, beta=0.1, robust_kld=False,
            num_steps=20000, batch_size=64, q_num_steps=4000, q_batch_size=16, q_lr=5e-4,
            baselines=("mojo_prior",),
        ),
    )
