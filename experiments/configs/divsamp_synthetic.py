# jaxmotion run --config experiments/configs/divsamp_synthetic.py --workdir /tmp/runs/divsamp_synthetic
# Same budget as the Bandai job (CVAE 2000 x 64, sampler 400 x 16, K = 50); not run for the README
# table (the CPU budget went to Bandai-Namco-2), expected runtime ~8 min on 2 CPU cores.
"""DivSamp on the built-in synthetic dataset (15 -> 60 frames, 16 joints, known modes).

The paper's architecture; loss weights chosen as for Bandai-Namco-2 (the authors' Human3.6M
values), which the synthetic future vector (60 x 48) resembles in size.
"""
from jaxmotion.config import Config
from jaxmotion.models.divsamp import DivSampConfig


def get_config() -> Config:
    return Config(
        name="divsamp_synthetic",
        method="divsamp",
        dataset="synthetic",
        eval_k=(50, 5),
        method_config=DivSampConfig(
            cvae_num_steps=2000, cvae_batch_size=64, cvae_lr_fix_fraction=0.2,
            num_steps=400, batch_size=16, nk=50, lr_fix_fraction=0.2,
            beta=0.5, lambda_kl=0.5, lambda_acc=40.0, lambda_div=20.0, eta=25.0, tau=1.0,
        ),
    )
