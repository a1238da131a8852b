# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_dense_long.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/motionmap_dense_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/motionmap_dense_s0
#
# MotionMap's long budget (motionmap_bandai_long.py: autoencoder 20,000 x 64, heatmap 20,000 x 64,
# finetune 10,000 x 64, curves every 1,000 steps at K = 7) on the dense map of motionmap_bandai_dense.py.
# Runtime (seed 0, 2-core AMD EPYC): 89 min: the 33,243 candidates' multimodal sets 16 min (transferred pair
# by pair; `motionmap_mm_sets` now gives the same sets in 28 s; cached in mm_cache_dir), t-SNE ~2 min, autoencoder 764 s, heatmap 2,830 s, finetune 239 s, evaluation ~3 min.
# Result (all 1,609 windows, K = 7, MotionMap's MM sets over training windows): MMADE / MMFDE 0.2880 / 0.3315
# (first map, motionmap_bandai_long.py: 0.3098 / 0.4255; DivSamp's long run 0.2902 / 0.3170); the release's
# K protocol (all peaks) 0.2862 / 0.3184 with 4.08 peaks per window; ADE 0.289. Curves flat by the end.
# experiments/results/motionmap.md, experiments/results/motionmap_tables_bandai_dense_long.md.
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
