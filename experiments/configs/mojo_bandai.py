# jaxmotion train --config experiments/configs/mojo_bandai.py --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/mojo_bandai
# jaxmotion eval  --config experiments/configs/mojo_bandai.py --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/mojo_bandai
# Shared Bandai budget: CVAE 2000 steps x 64, per-band DLow 400 steps x 16 with K = 50 (DLow-style lr schedule).
# Measured 2026-12-01 with the release's initialisation (PyTorch nn.Linear rule), seed 0,
# `jaxmotion run ... --seed 0`: 688 s on the 2-core AMD EPYC. K = 50, 1,609 windows, metres:
#   mojo        APD 8.503 ADE 0.2447 FDE 0.2918 MMADE 0.2955 MMFDE 0.3170 FSE 0.171 BDF 0.275 ADE-m 0.583
#   mojo_prior  APD 1.645 ADE 0.2830 FDE 0.3190 MMADE 0.3346 MMFDE 0.3459 FSE 0.004 BDF 0.068 (N(0, I) in all bands)
#   zero_vel.   APD 0.000 ADE 0.4328 FDE 0.4844 MMADE 0.4805 MMFDE 0.5144 FSE -0.472
# Before (flax initialisation): mojo APD 5.587 ADE 0.272 FDE 0.321 MMADE 0.314.
# Seed 1 (`python -m jaxmotion.cli run ... --seed 1`): mojo APD 8.615 ADE 0.2485 FDE 0.2941 MMADE 0.2979
#   MMFDE 0.3214 FSE 0.189 BDF 0.286; mojo_prior APD 1.638 ADE 0.2903 FDE 0.3226 MMADE 0.3400. Seed 2 not run yet.
"""MOJO on Bandai-Namco-2 joints (15 -> 60 frames at 30 fps, D = 60): latent DCT (60 bands x 16),
L1 + 3 x velocity L1 + robust KLD (Eq. (1)), residual decoder; DLow on the lowest 12 bands.

The second stage's lr is 5e-4 instead of the release's 1e-4, as in this project's DLow row
(`dlow_bandai.py`): 1e-4 is tuned for far more steps than the shared 400.
"""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_bandai",
        method="mojo",
        dataset="../shared/data/bandai-namco-2",
        eval_k=(50,),
        ckpt_every=500,
        method_config=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
