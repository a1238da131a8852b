# flock /tmp/jaxmotion-heavy.lock jaxmotion train --config experiments/configs/mojo_vae_dct5_humaneva_sq_recon.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/mojo_vae_dct5_humaneva_sq_recon_s0 --seed 0 --resume
"""A diagnostic of the VAE+DCT+5 row, not a row of the table: `mojo_vae_dct5_humaneva.py` with DLow's release's
best-of-K reconstruction term in the second stage (squared errors, `q_recon="sq"`) instead of MOJO's release's
(absolute errors), everything else the same.

The row's run came out more accurate and less diverse than MOJO's Table 2 (its learning curve: APD about 2.8
against 4.18, ADE 0.217 against 0.234). In the second stage's objective the diversity term (lambda_j 50, DLow's
HumanEva-I value) pulls against the reconstruction term (lambda_recon 2); DLow's release squares the errors, MOJO's
release sums their absolute values, which on HumanEva-I's metres weighs the reconstruction far more (the logged
terms late in training: about 8.5 summed absolute in the row's run, 0.25 summed squared in this one, against a
diversity term of about 0.65 times 50). This run asks how far that one difference moves APD, ADE and FDE. It starts from the row's seed-0 CVAE (its `cvae/` folder copied into this
run's folder, so `--resume` trains the second stage alone) and is compared point by point with the row's learning
curve over the same steps (the same learning-rate schedule), read on the test windows to compare with the paper's row.
"""
import dataclasses
from pathlib import Path

from jaxmotion.config import load_config


def get_config():
    base = load_config(Path(__file__).with_name("mojo_vae_dct5_humaneva.py"))
    return dataclasses.replace(base, name="mojo_vae_dct5_humaneva_sq_recon",
                               method_config=dataclasses.replace(base.method_config, q_recon="sq"))
