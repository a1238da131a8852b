# jaxmotion run --config experiments/configs/dlow_synthetic.py
# (the same as plain `jaxmotion run`: this file only spells the defaults out)
# Runtime and result: see experiments/results/dlow.md.
from jaxmotion.config import Config


def get_config() -> Config:
    return Config()
