# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/gsps_synthetic.py --workdir ~/jaxmotion-runs/gsps_synthetic
#
# GSPS on the built-in synthetic dataset (15 -> 60 frames at 30 fps, 16 joints + root, known modes).
# Budget for 2 CPU cores (the release trains the generator for 500 epochs x 5000 windows with
# nk1 x nk2 = 10 x 10 samples per window and a 256-wide GCN): prior 400 steps x 1024 frames,
# generator 2000 steps x 8 windows x (5 x 5) samples, GCN width 128. Loss weights: the release's
# Human3.6M values (the synthetic skeleton has Human3.6M's 17-joint layout).
# Runtime and result: see experiments/results/gsps.md.
from jaxmotion.config import Config
from jaxmotion.models.gsps import GSPSConfig


def get_config() -> Config:
    return Config(
        name="gsps_synthetic",
        method="gsps",
        dataset="synthetic",
        eval_k=(50, 5),
        method_config=GSPSConfig(
            prior_batch_size=1024, prior_num_steps=400,
            hidden=128, n_pre=10, nk1=5, nk2=5, batch_size=8, num_steps=2000, lr_fix_fraction=0.2,
            mm_candidate_stride=15,
        ),
    )
