# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/gsps_bandai_no_prior.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/gsps_bandai_no_prior
#
# GSPS ablation (the paper's supplementary Table 2): gsps_bandai.py without the pose-prior NLL term (lambda_prior 0.01 -> 0),
# everything else identical (budget, seed, data, pseudo ground truth). Compared with gsps_bandai.py by
# experiments/validity_table.py (bone deformation, angle violations, pose-prior NLL) and the end-pose
# picture of experiments/compare_methods.py.
# Runtime and result: not yet measured.
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("gsps_bandai.py"))
    return dataclasses.replace(base, name="gsps_bandai_no_prior", method_config=dataclasses.replace(base.method_config, lambda_prior=0.0))
