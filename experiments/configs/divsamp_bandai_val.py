# python -m jaxmotion.cli train --config experiments/configs/divsamp_bandai_val.py --data ../shared/data/bandai-namco-2 --workdir ~/jaxmotion-runs/ship/divsamp --seed 0
#
# divsamp_bandai.py (the shared Bandai budget) on the validation split of Bandai-Namco-2 (`Config.split = "val"`:
# one training clip in five per content held back, 1,428 windows; the test style is not read), no CMD / FID.
# A shipped model (jaxmotion/pretrained/) is trained here and compared with the others on the held-back
# windows (experiments/shipped_models.py); the test windows only measure the model that was chosen.
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("divsamp_bandai.py"))
    return dataclasses.replace(base, name="divsamp_bandai_val", split="val", action_metrics=False)
