# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/motionmap_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/motionmap_s0
#
# MotionMap on Bandai-Namco-2 at the long budget of issue 14: 10x the step counts of
# motionmap_bandai.py (autoencoder 20,000 x 64, heatmap 20,000 x 64, finetune 10,000 x 64), the
# release's loss weights and map as there; learning curves every 1,000 steps (K = 7, MotionMap's
# table's K, on 200 fixed test windows). Everything else as motionmap_bandai.py.
# Runtime, first try (seed 0, 2026-12-04 from 00:31 UTC, 2-core AMD EPYC family 26, frozen copy of 36155bf):
# autoencoder 20,000 steps 905 s, heatmap ~0.15 s per step (~50 min), finetune not reached when the session
# ended at heatmap step ~17,000: about 80 min in all expected. Before the heatmap step's speed-ups (Conv1x1,
# separable targets, huge pages: 4.8x) the heatmap stage alone was ~3.5 h on this machine.
# Partial result (K = 7, 200 curve windows, decoder before finetune): ADE 0.302 at heatmap step 6,000 and
# 0.295-0.302 from 9,000 to 15,000 (MMADE ~0.43): flat after about a third of the budget. Details: the
# MotionMap cell of experiments/README.md's claims table.
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
