# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/mojo_vae_dct_humaneva_dlow_loss.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/mojo_vae_dct_humaneva_dlow_loss_s0 --seed 0 [--resume]
"""A diagnostic of the VAE+DCT row, not a row of the table: `mojo_vae_dct_humaneva.py` with DLow's CVAE objective
(squared error + lambda_v 1000 x jump + beta 0.01 x Psi(KLD), the KLD summed per window) instead of MOJO's Eq. (1),
the rest the same (the row's header says why the row takes MOJO's). The runs in
`experiments/results/humaneva/dlow_loss/` were made with these settings, recorded under the row's name.
Full budget (CVAE 7,500 steps of 64): about 30 minutes on the 2-core CPU.
"""
import dataclasses
import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("mojo_vae_dct_humaneva", Path(__file__).with_name("mojo_vae_dct_humaneva.py"))
_base = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_base)


def get_config():
    return dataclasses.replace(_base.variant(0, loss="dlow"), name="mojo_vae_dct_humaneva_dlow_loss")
