# jaxmotion run --config experiments/configs/mojo_dct_synthetic.py --workdir /tmp/runs/mojo_dct_synthetic
# Budget as on Bandai: CVAE 2000 steps x 64, DLow 400 steps x 16 with K = 50.
# Runtime and result: not measured (the measured MOJO runs are the Bandai ones, experiments/results/mojo.md).
"""MOJO-DCT on the synthetic data: MOJO without the latent DCT space (one 128-d latent vector, plain
KLD with weight 0.1; the release's `amass_vanilla_nsamp50.yml`), same loss and residual decoder,
DLow on the one vector."""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_dct_synthetic",
        method="mojo",
        dataset="synthetic",
        eval_k=(50, 5),
        ckpt_every=500,
        method_config=MojoConfig(
            variant="MOJO-DCT", latent="vector", nz=128, residual=True, loss="mojo", alpha=3.0, beta=0.1, robust_kld=False,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=(),
        ),
    )
