"""The diffusion predictor on HumanEva-I at a twentieth of HumanMAC's release budget, everything else as
`diffusion_humaneva.py`.

The release's budget (391,281 steps of 64 windows) costs about 60 hours on a 2-core CPU (the Benchmarks page's
cost table: 0.57 s a step); this config trains 19,564 steps (5%), the step-decay milestones and the EMA start as
the release's (the milestones are fractions of the run, so they scale with it), and evaluates as the release
does (K = 50, 100 DDIM steps, the condition kept with probability 0.5). Its learning curve takes a point every
2,000 steps on 32 of the 188 test windows at K = 10 (read only for plotting: a point on every window at K = 50
and 100 DDIM steps costs about as long as the final evaluation). The Results page's HumanEva-I table states
the fraction beside the row.

    jaxmotion run --config experiments/configs/diffusion_humaneva_5pct.py --data PATH/data_3d_humaneva15.npz --seed 0
"""
from pathlib import Path

from jaxmotion.config import budget_fraction

FRACTION = 0.05


def get_config():
    return budget_fraction(Path(__file__).with_name("diffusion_humaneva.py"), FRACTION, name="diffusion_humaneva_5pct",
                           ckpt_every=1000, curve_every=2000, curve_windows=32, curve_k=10)
