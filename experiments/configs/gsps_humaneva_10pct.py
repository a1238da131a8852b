"""GSPS on HumanEva-I at a tenth of the release's generator budget, everything else as `gsps_humaneva.py`.

The release's generator budget (62,500 steps of 16 windows x 10 x 10 futures) costs tens of hours on a 2-core
CPU (the Benchmarks page's cost table); this config trains the flow prior at its full 1,200 steps and the
generator for 6,250 steps (10%), the learning-rate schedule scaled with it (constant for the first fifth, then
linear to 0, as the release's), with a learning curve every 625 steps on the 188 test windows (read only for
plotting). The Results page's HumanEva-I table states the fraction beside the row.

    jaxmotion run --config experiments/configs/gsps_humaneva_10pct.py --data PATH/data_3d_humaneva15.npz --seed 0
"""
from pathlib import Path

from jaxmotion.config import budget_fraction

FRACTION = 0.1


def get_config():
    return budget_fraction(Path(__file__).with_name("gsps_humaneva.py"), FRACTION, name="gsps_humaneva_10pct",
                           ckpt_every=625, curve_every=625)
