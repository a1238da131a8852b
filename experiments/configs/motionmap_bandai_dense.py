# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_bandai_dense.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/motionmap_bandai_dense
#
# MotionMap on Bandai-Namco-2 with the release's map density: motionmap_bandai.py's budget and settings,
# but training windows every 3 frames (0.1 s, the release's Human3.6M candidate spacing; 33,243
# windows), t-SNE fitted on every one of them (no transform), one multimodal member per map cell
# before the 64-member cap, and the release's K protocol beside ours (`motionmap_all_peaks`: the
# zero-velocity future and every peak; `distinct_futures` - 1 is its ANP).
# Why: the ground-truth maps of motionmap_bandai.py's map have 3.19 peaks per test window (>= 5 in
# 20.9%); this map's have 7.27 (>= 5 in 87.1%) (experiments/results/motionmap.md; experiments/motionmap_target_peaks.py).
# Trained at the long budget only (motionmap_bandai_dense_long.py, where its runtime and result are).
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("motionmap_bandai.py"))
    return dataclasses.replace(
        base, name="motionmap_bandai_dense",
        method_config=dataclasses.replace(
            base.method_config, pool_stride=3, tsne_fit_points=None, dedupe_members=True, k_protocol="release"
        ),
    )
