# jaxmotion train --config experiments/configs/mojo_bandai_markers.py --data ../shared/data/bandai-namco-2 --workdir runs/mojo_bandai_markers
# jaxmotion eval  --config experiments/configs/mojo_bandai_markers.py --data ../shared/data/bandai-namco-2 --workdir runs/mojo_bandai_markers
# python experiments/mojo_projection_table.py --workdir runs/mojo_bandai_markers   (with vs without recursive projection)
# Shared Bandai budget: CVAE 2000 steps x 64, per-band DLow 400 steps x 16 with K = 50.
"""MOJO on Bandai-Namco-2 as body-surface markers: the Bandai skeleton body carrying the `bandai`
(CMU-41) markers, driven by every clip (`jaxmotion.body.marker_data.load_bandai_markers`); global
marker positions in the canonical frame of each window's first frame (PROTOCOL sec. 4), D = 123.
Same split, rate and window lengths as `mojo_bandai.py` (15 -> 60 frames at 30 fps) and the same
model and budget. Recursive projection (`mojo_proj`) is evaluated by `experiments/mojo_projection_table.py`
on a subset of windows: it fits the body 60 times per sample and window.
"""
from jaxmotion.config import Config
from jaxmotion.models.mojo import MojoConfig


def get_config() -> Config:
    return Config(
        name="mojo_bandai_markers",
        method="mojo",
        dataset="../shared/data/bandai-namco-2",
        data_options={"markers": "bandai"},
        eval_k=(50,),
        ckpt_every=500,
        mojo=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
