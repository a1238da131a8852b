# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/dlow_bandai_long_scaled.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/long/dlow_scaled_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/long/dlow_scaled_s0
#
# DLow on Bandai-Namco-2 at the long budget with the Q network's d_scale from the data:
# `jaxmotion.diversity.dlow_d_scale` on the training windows' spread gives 32.6
# (`python experiments/diversity_scale.py --data ../shared/data/bandai-namco-2`; the release uses 100 for
# Human3.6M and 20 for HumanEva-I); the validation sweep (dlow_bandai_val.py) did not overturn it.
# Everything else as dlow_bandai_long.py, the earlier long run with the release's Human3.6M value (100).
# Only the Q stage differs: copying a trained dlow_bandai_long run's `cvae/` folder into the work directory
# and running with --resume trains the Q network alone (~35 min quiet on a 2-core CPU).
# Runtime (seed 0, 2-core AMD EPYC): 2,185 s from start to report (CVAE ~20 min, Q networks for K = 50 and 5).
# Result (K = 50, all 1,609 test windows): DLow APD 3.438, ADE 0.1630, FDE 0.1592, MMADE 0.2507; d_scale 100,
# the same seed: 2.862 / 0.1615 / 0.1579 / 0.2567; its CVAE 2.105 / 0.1576 (experiments/results/dlow.md).
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("dlow_bandai_long.py"))
    m = base.method_config
    return dataclasses.replace(base, name="dlow_bandai_long_scaled",
                               method_config=dataclasses.replace(m, q=dataclasses.replace(m.q, d_scale=32.6)))
