# jaxmotion run --config experiments/configs/dlow_synthetic.py
# (the same as plain `jaxmotion run`: this file only spells the defaults out)
# Runtime and result: see README.md ("Measured").
from jaxmotion.config import Config


def get_config() -> Config:
    return Config()
