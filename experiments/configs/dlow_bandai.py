# jaxmotion run --config experiments/configs/dlow_bandai.py --data ../shared/data/bandai-namco-2 --workdir runs/dlow_bandai
#
# DLow (CVAE + Q network, K = 50) on Bandai-Namco-2 under PROTOCOL sec. 3: 30 fps, 15 -> 60 frames,
# 20 joints relative to Hips (D = 60), train styles active/exhausted/feminine/masculine (1,722
# sequences, 99,746 train windows), test style normal (465 sequences, 1,609 windows, stride 15).
# MM ground truth at threshold 0.5: 177.1 futures per window on average (min 5, max 282; no window
# has only itself).
# Budget (shared by the method tables on Bandai): CVAE 2000 steps x 64, Q network 400 steps x 16.
# Runtime: 620 s on the 2-core CPU with light load (data 7 s, CVAE ~5 min, Q ~2.5 min, eval ~1.5 min);
# 27.7 min measured while other jobs shared the 2 cores.
#
# Measured (seed 0, K = 50, 1,609 windows), metres:
#   method          APD     ADE     FDE     MMADE   MMFDE   ADE-m   FDE-m
#   zero-velocity   0.000   0.4328  0.4844  0.4805  0.5144  0.4328  0.4844
#   CVAE, N(0, I)   1.302   0.3518  0.3930  0.3795  0.4066  0.3835  0.4619
#   DLow            2.225   0.3523  0.3927  0.3789  0.4059  0.3867  0.4665
#
# Why beta = 0.3 (the paper uses 0.1 with ~39k CVAE steps; we have 2k): measured on this budget,
#   beta 0.1, Q lr 5e-4:           DLow APD 14.80, ADE 0.3703, ADE-m 1.95 (most samples are broken bodies)
#   beta 0.1, Q lr 1e-4 (paper):   DLow APD 14.65, ADE 0.3668, ADE-m 1.95 (same)
#   beta 0.1, Q lr 5e-4, KL x10:   DLow APD  9.39, ADE 0.4039, ADE-m 0.78 (many broken bodies)
#   beta 1.0:                      CVAE KL collapses to 0.07 nats, DLow cannot diversify (div loss 0.99)
#   beta 0.3 (this config):        plausible samples (ADE-m 0.39) but little diversity (APD 2.2).
# At this budget the decoder is not trained enough to be both diverse and plausible away from its
# posterior; longer training (the paper's 500 epochs) is the fix, and this config is the honest
# plausible point. DLow beats zero-velocity on ADE/FDE and its own CVAE on APD.
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_bandai",
        dataset="../shared/data/bandai-namco-2",
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=2000, batch_size=64, beta=0.3),
            # Q lr 5e-4 instead of the paper's 1e-4: 400 steps instead of ~15k.
            q=QConfig(num_steps=400, batch_size=16, lr=5e-4),
        ),
        eval_k=(50,),
        ckpt_every=500,
    )
