# jaxmotion train --config experiments/configs/mojo_synthetic.py --workdir /tmp/runs/mojo_synthetic
# jaxmotion eval  --config experiments/configs/mojo_synthetic.py --workdir /tmp/runs/mojo_synthetic
# Budget as on Bandai: CVAE 2000 steps x 64, per-band DLow 400 steps x 16 with K = 50 (DLow-style lr schedule).
# Runtime and result: not measured (the measured MOJO runs are the Bandai ones, experiments/results/mojo.md).
"""MOJO on the built-in synthetic data (15 -> 60 frames, D = 48): latent DCT (60 bands x 16),
L1 + 3 x velocity L1 + robust KLD (Eq. (1)), residual decoder; DLow on the lowest 12 bands.

The second stage's lr is 5e-4 instead of the release's 1e-4, as in this project's DLow row
on Bandai (`dlow_bandai.py`): 1e-4 is tuned for far more steps than the shared 400.
"""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_synthetic",
        method="mojo",
        dataset="synthetic",
        eval_k=(50, 5),
        ckpt_every=500,
        method_config=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
