# jaxmotion train --config experiments/configs/mojo_bandai_markers.py --data ../shared/data/bandai-namco-2 --workdir runs/mojo_bandai_markers
# jaxmotion eval  --config experiments/configs/mojo_bandai_markers.py --data ../shared/data/bandai-namco-2 --workdir runs/mojo_bandai_markers
# python experiments/mojo_projection_table.py --workdir runs/mojo_bandai_markers --windows 128   (with vs without projection)
# Shared Bandai budget: CVAE 2000 steps x 64, per-band DLow 400 steps x 16 with K = 50.
# Runtime: train 10.3 min, eval 3.7 min, projection table (128 windows) 10.6 min (2 CPU cores). Result (K = 50, 1,609 windows,
# distances over the 123-number frame):
#   mojo        APD 27.27 ADE 0.624 FDE 0.951 MMADE 0.690 MMFDE 0.993 BDF 0.167 m foot skating 0.448
#   mojo_prior  APD  7.72 ADE 1.034 FDE 1.949 MMADE 1.074 MMFDE 1.954 BDF 0.128 m
#   zero_vel.   APD  0    ADE 4.102 FDE 7.796
# 128 windows, same latents: mojo BDF 0.165 m, head/lower torso 154/142 mm; mojo_proj BDF 3e-7 m, 0/0 mm,
# APD 26.9 -> 20.0, ADE 0.600 -> 0.665 (experiments/results/body.md).
"""MOJO on Bandai-Namco-2 as body-surface markers: the Bandai skeleton body carrying the `bandai`
(CMU-41) markers, driven by every clip (`jaxmotion.data.markers.load_bandai_markers`); global
marker positions in the canonical frame of each window's first frame (protocol §5 (docs/pages/protocol.md#marker-canonicalisation)), D = 123.
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
        method_config=MojoConfig(
            variant="MOJO", latent="dct", nz=16, residual=True, loss="mojo", alpha=3.0, beta=1.0, robust_kld=True,
            num_steps=2000, batch_size=64, q_num_steps=400, q_batch_size=16, q_lr=5e-4,
            baselines=("zero_velocity", "mojo_prior"),
        ),
    )
