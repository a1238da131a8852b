# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_dense_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/motionmap_dense_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/motionmap_dense_s0
#
# MotionMap's long budget (motionmap_bandai_long.py: autoencoder 20,000 x 64, heatmap 20,000 x 64,
# finetune 10,000 x 64, curves every 1,000 steps at K = 7) on the dense map of motionmap_bandai_dense.py.
# Runtime and result: not measured yet.
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("motionmap_bandai_dense.py"))
    c = base.method_config
    return dataclasses.replace(
        base, name="motionmap_bandai_dense_long", curve_every=1000, curve_k=7,
        method_config=dataclasses.replace(c, ae_steps=10 * c.ae_steps, hm_steps=10 * c.hm_steps, ft_steps=10 * c.ft_steps),
    )
