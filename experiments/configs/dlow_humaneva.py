# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/dlow_humaneva.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/dlow_humaneva_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/humaneva/dlow_humaneva_s0
"""DLow on HumanEva-I at the release's full budget (`motion_pred/cfg/humaneva_nsamp50.yml` of the DLow release).

CVAE: nz 128, beta 0.01, lambda_v 1000, lr 1e-3, batch 64, 500 epochs of 1,000 sampled windows
(15 batches an epoch: 7,500 steps), lr constant for 100 epochs then linear decay to 0.
Q network (NFDiag, MLP 1024-512): K = 50, batch 32, d_scale 20, lambda_j 50, lambda_recon 2,
lr 1e-4, 500 epochs of 1,000 windows (31 batches an epoch: 15,500 steps), same schedule.
The paper's row (DivSamp's Table 1): APD 4.855, ADE 0.251, FDE 0.268, MMADE 0.362, MMFDE 0.339.
Learning curves every 500 steps on the test windows (K = 50), read only for plotting.
"""
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_humaneva",
        dataset="data_3d_humaneva15.npz",
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=500 * (1000 // 64), batch_size=64, beta=0.01, lambda_v=1000.0, lr=1e-3),
            q=QConfig(num_steps=500 * (1000 // 32), batch_size=32, lr=1e-4, d_scale=20.0, lambda_j=50.0,
                      lambda_recon=2.0),
        ),
        eval_k=(50,),
        train_sampler="subjects",  # the release draws a subject, then a take, then a start (dataset.py `sample`)
        ckpt_every=500,
        curve_every=500,
    )
