# jaxmotion run --config experiments/configs/dlow_synthetic.py
# (the same as plain `jaxmotion run`: this file only spells the defaults out)
# Runtime and result: see experiments/results/README.md ("The default job and Bandai-Namco-2").
from jaxmotion.config import Config


def get_config() -> Config:
    return Config()
