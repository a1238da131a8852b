# flock /tmp/jaxmotion-heavy.lock jaxmotion train --config experiments/configs/mojo_vae_dct20_humaneva_dlow_loss.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/mojo_vae_dct20_humaneva_dlow_loss_s0 --seed 0 --resume
"""A diagnostic of the VAE+DCT+20 row, not a row of the table: `mojo_vae_dct5_humaneva_dlow_loss.py` (DLow's objectives
in both stages, from the plain-KLD VAE+DCT diagnostic's CVAE) with DLow on the lowest 20 of 60 bands, as
`mojo_vae_dct20_humaneva.py`: the same question for the +20 row, read against its learning curve over the same steps.
"""
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    five = load_config(Path(__file__).with_name("mojo_vae_dct5_humaneva_dlow_loss.py"))
    row = load_config(Path(__file__).with_name("mojo_vae_dct20_humaneva.py")).method_config
    return dataclasses.replace(five, name="mojo_vae_dct20_humaneva_dlow_loss", method_config=dataclasses.replace(
        five.method_config, variant=row.variant, dlow_band_fraction=row.dlow_band_fraction))
