# jaxmotion run --config experiments/configs/mojo_dct_bandai.py --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/mojo_dct_bandai
# Shared Bandai budget: CVAE 2000 steps x 64, DLow 400 steps x 16 with K = 50.
# Runtime: 14 min (2 shared CPU cores); 8.2 min for `jaxmotion run` on 2026-12-01 (AMD EPYC, other jobs
# sharing the cores). Result (K = 50, 1,609 windows, seed 0), metres:
#   mojo (MOJO-DCT)  APD 0.167 ADE 0.342 FDE 0.431 MMADE 0.383 MMFDE 0.450 FSE -0.016
# (before the CVAE was shared with DLow: APD 0.173, ADE-m 0.410, BDF 0.087; the decoder now hoists
# the vector latent's share of the GRU input out of the time loop, as DLow's does: the same maths,
# float32 rounding in another order, so 2000 steps later the numbers move in the third decimal.)
"""MOJO-DCT on Bandai-Namco-2: MOJO without the latent DCT space (one 128-d latent vector, plain
KLD with weight 0.1; the release's `amass_vanilla_nsamp50.yml`), same loss and residual decoder,
DLow on the one vector."""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_dct_bandai",
        method="mojo",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50,),
        ckpt_every=500,
        method_config=MojoConfig(
            variant="MOJO-DCT", latent="vector", nz=128, residual=True, loss="mojo", alpha=3.0, beta=0.1, robust_kld=False,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=(),
        ),
    )
