# jaxmotion run --config experiments/configs/mojo_vae_dct_synthetic.py --workdir /tmp/runs/mojo_vae_dct_synthetic
# Budget as on Bandai: CVAE 2000 steps x 64, DLow 400 steps x 16 with K = 50.
# Runtime and result: not measured (the measured MOJO runs are the Bandai ones, experiments/results/mojo.md).
"""VAE+DCT and VAE+DCT+L on the synthetic data: DLow's CVAE objective (squared error, jump loss
lambda_v = 1000, KLD weight 0.1) and decoder without residual output, with MOJO's latent DCT
space (60 bands x 16). One trained CVAE gives both rows: "mojo_prior" = VAE+DCT (N(0, I) in every
band), "mojo" = VAE+DCT+L (DLow on the lowest 12 bands)."""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_vae_dct_synthetic",
        method="mojo",
        dataset="synthetic",
        eval_k=(50, 5),
        ckpt_every=500,
        method_config=MojoConfig(
            variant="VAE+DCT", latent="dct", nz=16, residual=False, loss="dlow", beta=0.1, robust_kld=False,
            lambda_v=1000.0, num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=("mojo_prior",),
        ),
    )
