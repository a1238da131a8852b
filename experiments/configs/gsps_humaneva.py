# jaxmotion run --config experiments/configs/gsps_humaneva.py --data /path/to/data_3d_humaneva15.npz --workdir runs/gsps_humaneva
# Not run here (HumanEva-I is licensed and absent). The paper reports APD 5.825, ADE 0.233, FDE 0.244,
# MMADE 0.343, MMFDE 0.331 (K = 50). Runtime: 62,500 generator steps of 16 windows x 100 samples,
# most of a day on one GPU; days on this 2-core CPU (about 3 s per step, from gsps_bandai.py's
# measured step scaled to 10 x 10 samples and 14 joints).
"""GSPS on HumanEva-I (15 -> 60 frames at 60 fps, 14 joints): the authors' released settings.

`motion_pred/cfg/humaneva_nf.yml` and `humaneva.yml` of github.com/wei-mao-2019/gsps: the pose
prior as for Human3.6M (3 LinQR layers, lr 1e-2, batch 4096, 25 epochs of 200,000 frames, 5
constant); generator GCNs of 256 features and 4 residual blocks, nz 64, n_pre 8 DCT coefficients,
parts lower body then upper body (`parts: [[7..12], [0..6, 13]]`), nk1 x nk2 = 10 x 10, batch 16,
lr 1e-3, 500 epochs of 2000 windows (62,500 steps) constant for 100 epochs; loss weights
`lambdas: [100, 500, 5, 10, 2, 1, 0.01, 0.01, 100]`, `alphas: [15, 50]` (alpha, beta); pseudo
ground-truth candidates every 15 training frames (`..._skiprate15`), future at least 0.01 m away
(`t_pred60_thre0.010`).
"""
from jaxmotion.config import Config
from jaxmotion.models.gsps import GSPSConfig


def get_config() -> Config:
    return Config(
        name="gsps_humaneva",
        method="gsps",
        dataset="data_3d_humaneva15.npz",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        method_config=GSPSConfig(
            prior_layers=3, prior_lr=1e-2, prior_weight_decay=1e-3, prior_batch_size=4096,
            prior_num_steps=25 * 200_000 // 4096, prior_lr_fix_fraction=5 / 25,
            parts="lower_upper", n_pre=8, hidden=256, num_stage=4, nz=64, nk1=10, nk2=10,
            lr=1e-3, batch_size=16, num_steps=500 * 2000 // 16, lr_fix_fraction=100 / 500, grad_clip=100.0,
            lambda_his=100.0, lambda_limb=500.0, lambda_div_first=5.0, lambda_div_rest=10.0, alpha=15.0, beta=50.0,
            lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01, prior_stride=3, lambda_angle=100.0,
            mm_candidate_stride=15, mm_pred_threshold=0.01,
        ),
    )
