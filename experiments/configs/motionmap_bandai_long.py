# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/motionmap_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/motionmap_s0
#
# MotionMap on Bandai-Namco-2 at the long budget: 10x the step counts of
# motionmap_bandai.py (autoencoder 20,000 x 64, heatmap 20,000 x 64, finetune 10,000 x 64), the
# release's loss weights and map as there; learning curves every 1,000 steps (K = 7, MotionMap's
# table's K, on 200 fixed test windows). Everything else as motionmap_bandai.py.
# Runtime (seed 0, 2-core AMD EPYC, resumed once from the step-15,000 heatmap checkpoint): 68 min of training (autoencoder 905 s, heatmap ~0.14 s per step, 2,860 s, finetune 284 s),
# plus evaluation. Before the heatmap step's speed-ups (Conv1x1, separable targets, huge pages: 4.8x)
# the heatmap stage alone was ~3.5 h on this machine.
# Result (all 1,609 windows, K = 7, MM against training windows): APD 1.478, ADE 0.272, FDE 0.354,
# MMADE 0.3098, MMFDE 0.4255 (shared budget: ADE 0.310, MMADE 0.363); 1.95 peaks per window. Both stages'
# learning curves were flat by the end (heatmap from about step 6,000; finetune ADE -0.3% over its last
# 20%). MotionMap's claim (best MMADE / MMFDE at small K) still does not hold: DivSamp's long run has
# 0.2902 / 0.3170. Details: experiments/results/motionmap.md and
# experiments/results/motionmap_tables_bandai_long.md.
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
