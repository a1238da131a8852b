# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/motionmap_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/motionmap_s0
#
# MotionMap on Bandai-Namco-2 at the long budget of issue 14: 10x the step counts of
# motionmap_bandai.py (autoencoder 20,000 x 64, heatmap 20,000 x 64, finetune 10,000 x 64), the
# release's loss weights and map as there; learning curves every 1,000 steps (K = 7, MotionMap's
# table's K, on 200 fixed test windows). Everything else as motionmap_bandai.py.
# Expected runtime (not yet run end to end): about 75 min on the 2-core AMD EPYC of 2026-12-03 with
# the heatmap step's speed-ups (Conv1x1, separable targets, huge pages: ~0.13 s per heatmap step,
# ~0.04 s per autoencoder step, measured under load and scaled), several hours before them.
# Result: experiments/README.md, "Long budget: MotionMap" once run.
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("motionmap_bandai.py"))
    c = base.method_config
    return dataclasses.replace(
        base, name="motionmap_bandai_long", curve_every=1000, curve_k=7,
        method_config=dataclasses.replace(c, ae_steps=10 * c.ae_steps, hm_steps=10 * c.hm_steps, ft_steps=10 * c.ft_steps),
    )
