# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/mojo_vae_dct5_humaneva.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/mojo_vae_dct5_humaneva_s0 --seed 0 [--resume]
#
# MOJO's VAE+DCT+5 on HumanEva-I (DLow on the lowest 5 of 60 DCT bands): mojo_vae_dct_humaneva.py says
# which settings and why. Its "mojo_prior" predictor is the same run's VAE+DCT.
import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("mojo_vae_dct_humaneva", Path(__file__).with_name("mojo_vae_dct_humaneva.py"))
_base = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_base)


def get_config():
    return _base.variant(5)
