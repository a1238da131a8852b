# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/dlow_bandai_val.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/val/dlow_rule_s0 --seed 0
#
# DLow's `d_scale` chosen on the validation split of Bandai-Namco-2 (`Config.split = "val"`: one
# training clip in five per content held back, 1,428 windows; the test style is not read): the
# budget and settings of dlow_bandai.py with the split and the Q network's d_scale below (no CMD / FID).
#   h36m      100, the release's Human3.6M value (every earlier Bandai config), dlow_bandai_val_h36m.py
#   rule      32.6, `jaxmotion.diversity.dlow_d_scale` on the training windows' spread
#             (`python experiments/diversity_scale.py --data ../shared/data/bandai-namco-2`: s = 0.466 m;
#             the rule gives 89.1 for Human3.6M and 22.5 for HumanEva-I, whose releases use 100 and 20), this file
#   humaneva  20, the release's HumanEva-I value, dlow_bandai_val_humaneva.py
# The three share one CVAE (the Q network's d_scale does not reach the CVAE stage): the rule run
# trains it, the others start from a copy of its `cvae/` folder with --resume.
# Sweep results: not run yet (experiments/results/diversity.md).
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config

VARIANTS = {"h36m": 100.0, "rule": 32.6, "humaneva": 20.0}


def variant(name: str):
    base = load_config(Path(__file__).with_name("dlow_bandai.py"))
    m = base.method_config
    return dataclasses.replace(
        base, name=f"dlow_bandai_val_{name}", split="val", action_metrics=False,
        method_config=dataclasses.replace(m, q=dataclasses.replace(m.q, d_scale=VARIANTS[name])),
    )


def get_config():
    return variant("rule")
