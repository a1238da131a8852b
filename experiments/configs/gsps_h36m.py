# jaxmotion run --config experiments/configs/gsps_h36m.py --data /path/to/data_3d_h36m.npz --workdir runs/gsps_h36m
# Not run here (Human3.6M is licensed and absent). The paper reports APD 14.757, ADE 0.389, FDE 0.496,
# MMADE 0.476, MMFDE 0.525 (K = 50). Runtime: the generator's 156,250 steps of 16 windows x 100
# samples are days on one GPU; on this 2-core CPU, extrapolating gsps_bandai.py's measured 1.16 s
# per step (5 x 5 samples) to 10 x 10 samples, about 4.6 s per step, i.e. over a week.
"""GSPS on Human3.6M (25 -> 100 frames at 50 fps, 16 joints): the authors' released settings.

`motion_pred/cfg/h36m_nf.yml` and `h36m.yml` of github.com/wei-mao-2019/gsps, which are also
`GSPSConfig`'s defaults (written out here so the budget reads in one place):
pose prior 3 LinQR layers, Adam lr 1e-2 (weight decay 1e-3), batch 4096, 25 epochs of 200,000
frames (1220 steps), constant for 5 epochs then linear decay; generator GCNs of 256 features and 4
residual blocks, nz 64, n_pre 10 DCT coefficients, parts lower body then upper body
(`parts: [[0..5], [6..15]]`), nk1 x nk2 = 10 x 10 samples per window, batch 16, lr 1e-3, 500
epochs of 5000 windows (156,250 steps) constant for 100 epochs, gradient clipping at norm 100;
loss weights `lambdas: [100, 500, 8, 25, 2, 1, 0.01, 0.01, 100]` (past, limb, lower / upper
diversity, best-of-K, multimodal, prior NLL and prior log-det (the release leaves that term
commented out; see models/gsps.py), angle), alpha 100, beta 300; pseudo ground-truth
candidates every 20 training frames (`data_candi_..._skiprate20`), future at least 0.1 m away.
"""
from jaxmotion.config import Config
from jaxmotion.models.gsps import GSPSConfig


def get_config() -> Config:
    return Config(
        name="gsps_h36m",
        method="gsps",
        dataset="data_3d_h36m.npz",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        method_config=GSPSConfig(
            prior_layers=3, prior_lr=1e-2, prior_weight_decay=1e-3, prior_batch_size=4096,
            prior_num_steps=25 * 200_000 // 4096, prior_lr_fix_fraction=5 / 25,
            parts="lower_upper", n_pre=10, hidden=256, num_stage=4, nz=64, nk1=10, nk2=10,
            lr=1e-3, batch_size=16, num_steps=500 * 5000 // 16, lr_fix_fraction=100 / 500, grad_clip=100.0,
            lambda_his=100.0, lambda_limb=500.0, lambda_div_first=8.0, lambda_div_rest=25.0, alpha=100.0, beta=300.0,
            lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01, prior_stride=3, lambda_angle=100.0,
            mm_candidate_stride=20, mm_pred_threshold=0.1,
        ),
    )
