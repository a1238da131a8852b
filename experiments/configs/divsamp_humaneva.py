# jaxmotion run --config experiments/configs/divsamp_humaneva.py --data /path/to/data_3d_humaneva15.npz --workdir runs/divsamp_humaneva
# Not run here (HumanEva-I is licensed and absent). The paper reports APD 6.109, ADE 0.220, FDE 0.234,
# MMADE 0.342, MMFDE 0.316 (K = 50).
"""DivSamp on HumanEva-I (15 -> 60 frames at 60 fps, 14 joints): the authors' released settings.

`humaneva/configs/config_cvae.py` and `config_diverse_sampling.py` of github.com/Droliven/diverse_sampling:
CVAE 2000 epochs of 2000 windows at batch 32 (62 steps an epoch), lr 1e-3 constant for 150 epochs,
KL weight 0.05; sampler 1500 epochs at batch 16 (125 steps an epoch), lr 1e-3 constant for 100
epochs, K = 50, lambda_kl 0.1, lambda_acc 25, lambda_div 100, eta 20, and no Tanh after the base
matrix's BatchNorm (the HumanEva-I release drops it). The paper states tau = 1; the release uses 0.85.
"""
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig


def get_config() -> Config:
    return Config(
        name="divsamp_humaneva",
        method="divsamp",
        dataset="data_3d_humaneva15.npz",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        method_config=DivSampConfig(
            cvae_num_steps=2000 * (2000 // 32), cvae_batch_size=32, cvae_lr_fix_fraction=150 / 2000, beta=0.05,
            num_steps=1500 * (2000 // 16), batch_size=16, nk=50, lr_fix_fraction=100 / 1500,
            lambda_kl=0.1, lambda_acc=25.0, lambda_div=100.0, eta=20.0, tau=1.0, base_tanh=False,
        ),
    )
