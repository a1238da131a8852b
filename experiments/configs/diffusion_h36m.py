# jaxmotion run --config experiments/configs/diffusion_h36m.py --data /path/to/data_3d_h36m.npz --workdir runs/diffusion_h36m
# Not run here (Human3.6M is licensed and absent). HumanMAC reports ADE 0.369 at K = 50. Runtime: 500 epochs of 50,000 windows (390,000 steps of 64) with a
# 8-block width-512 transformer are days on one GPU, and sampling 50 futures takes 100 DDIM steps.
"""The diffusion predictor on Human3.6M (25 -> 100 frames at 50 fps, 16 joints): the release's sizes.

`cfg/h36m.yml` of github.com/LinghaoChan/HumanMAC: 20 DCT coefficients of the 125-frame window,
padding with the last observed frame, 8 blocks, 8 heads, width 512 (feed-forward 1024, the
transformer's default), dropout 0.2, 1000 noise steps on the cosine schedule, 100 DDIM steps with
DCT completion, condition kept for 80% of training windows (`mod_train: 0.8`) and always at test,
Adam lr 3e-4 (the release steps it by 0.9 at epochs 75, 150, 225, 275, 350, 450; here: constant for
the first 75 of 500 epochs, then linear to 0), batch 64, EMA 0.995 after 2,000 steps.
"""
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig


def get_config() -> Config:
    return Config(
        name="diffusion_h36m",
        method="diffusion",
        dataset="data_3d_h36m.npz",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        method_config=DiffusionConfig(
            n_dct=20, latent=512, ff=1024, num_layers=8, num_heads=8, dropout=0.2, noise_steps=1000,
            schedule="cosine", sampling_steps=100, cond_drop=0.2, ema_decay=0.995, ema_start=2000, lr=3e-4,
            batch_size=64, num_steps=500 * 50_000 // 64, lr_fix_fraction=75 / 500,
        ),
    )
