# jaxmotion run --config experiments/configs/mojo_amass.py --data amass:/path/to/AMASS --workdir runs/mojo_amass
#
# AMASS is licensed and not shipped: register at amass.is.tue.mpg.de, download the "SMPL-H G"
# archives of CMU and HDM05 (train) and ACCAD and BMLhandball (test) and extract them into one
# folder (/path/to/AMASS/ACCAD/Female1General_c3d/..._poses.npz, ...). The markers are vertices of
# SMPL-X, also licensed: smpl-x.is.tue.mpg.de, SMPLX_NEUTRAL.npz / SMPLX_MALE.npz / SMPLX_FEMALE.npz
# in $JAXMOTION_SMPLX (default ~/body_models/smplx); the gendered files are used as MOJO did. The
# marker vertex ids are MOJO's CMU.json (41 markers; SSM2.json for 67), linked from the README of
# github.com/yz-cnsdqz/MOJO-release, at $JAXMOTION_MOJO_MARKERS (default ~/body_models/CMU.json).
# Not run here (neither data nor models are available): no runtime or result has been measured.
# The first run computes the markers of every sequence once (cached in ~/.cache/jaxmotion/amass).
"""MOJO on AMASS body-surface markers under MOJO's protocol (protocol §4 (docs/pages/protocol.md#datasets), protocol §5 (docs/pages/protocol.md#marker-canonicalisation)): the CMU-41 markers
of SMPL-X driven by each file's root and body pose and betas[:10], 15 fps (every 8th frame at 120
fps), 15 -> 45 frames, each window in the canonical frame of its first frame (D = 123), MM
threshold 0.5; train CMU, HDM05 / test ACCAD and BMLhandball together (MOJO reports them apart:
`"test_subsets": ["ACCAD"]` in `data_options`). Test windows start every 15 frames; MOJO's release
evaluates one window per non-overlapping 4 s chunk, every 4th of these.

Model and budget: `amass_mojo_f9_nsamp50.yml` of the release (nz 16 per DCT band, DLow on the
lowest 9 of 45 bands, robust KLD, alpha 3; CVAE 500 epochs x 5000 windows / batch 64, DLow 500
epochs x 1000 windows / batch 32, lr 1e-4), GRU width 128 as this project's other MOJO configs.
Recursive projection (`mojo_proj`) needs one body for every sequence: a single model file as
`model_path` (e.g. SMPLX_NEUTRAL.npz) instead of the gendered folder.
"""
import os

from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_amass",
        method="mojo",
        dataset="amass:~/data/AMASS",
        data_options={
            "protocol": "mojo",
            "model_path": os.environ.get("JAXMOTION_SMPLX", "~/body_models/smplx"),
            "marker_vertices": os.environ.get("JAXMOTION_MOJO_MARKERS", "~/body_models/CMU.json"),
        },
        eval_k=(50,),
        ckpt_every=2000,
        log_every=200,
        method_config=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=500 * 5000 // 64, batch_size=64, dlow_band_fraction=9 / 45,
            q_num_steps=500 * 1000 // 32, q_batch_size=32, q_lr=1e-4, d_scale=100.0, lambda_j=25.0, lambda_recon=2.0,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
