# jaxmotion run --config experiments/configs/divsamp_h36m.py --data /path/to/data_3d_h36m.npz --workdir runs/divsamp_h36m
# Not run here (Human3.6M is licensed and absent). The paper reports APD 15.310, ADE 0.370, FDE 0.485,
# MMADE 0.475, MMFDE 0.516 (K = 50); expect days on one GPU at this budget, far longer on a CPU.
"""DivSamp on Human3.6M (25 -> 100 frames at 50 fps, 16 joints): the authors' released settings.

`h36m/configs/config_cvae.py` and `config_diverse_sampling.py` of github.com/Droliven/diverse_sampling:
CVAE 2000 epochs of 5000 windows at batch 64 (78 steps an epoch), lr 1e-3 constant for 100 epochs
then linear decay, KL weight 0.5; sampler 1500 epochs at batch 16 (312 steps an epoch), lr 1e-3
constant for 100 epochs, K = 50, lambda_kl 0.5, lambda_acc 40, lambda_div 20, eta 25. The paper
states tau = 1; the released config uses 0.85.
"""
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig


def get_config() -> Config:
    return Config(
        name="divsamp_h36m",
        method="divsamp",
        dataset="data_3d_h36m.npz",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        method_config=DivSampConfig(
            cvae_num_steps=2000 * (5000 // 64), cvae_batch_size=64, cvae_lr_fix_fraction=100 / 2000, beta=0.5,
            num_steps=1500 * (5000 // 16), batch_size=16, nk=50, lr_fix_fraction=100 / 1500,
            lambda_kl=0.5, lambda_acc=40.0, lambda_div=20.0, eta=25.0, tau=1.0, base_tanh=True,
        ),
    )
