# jaxmotion run --config experiments/configs/dlow_cmu_bvh.py --data ../shared/data/cmu-bvh --workdir runs/dlow_cmu_bvh
#
# A plain folder of BVH clips end to end (docs/pages/own-data.md): the two CMU trials of subject 01. The folder
# has one subject, so the default split holds out the last 20% of files (at least one): 01_01.bvh
# trains, 01_03.bvh is the test file (`--test-files 01_01` swaps them). Each file is resampled from
# its own rate to 30 fps (120 -> 30 here, data_options "fps"), so the protocol is 0.5 s -> 2 s = 15 -> 60 frames,
# 31 joints relative to Hips (D = 90): 614 training windows, 71 test windows (stride 15).
# A small budget: this shows the pipeline on a user's own clips, it is not a benchmark (one training
# trial of 23 s is far too little data for a stochastic model).
# Runtime: 37 s on the 2-core CPU (data 0.4 s, CVAE 300 steps x 32, Q 100 steps x 16, eval, report).
# Measured (seed 0, K = 10, 71 windows), metres (norm over the whole D = 90 vector, protocol §2 (docs/pages/protocol.md#metrics)):
#   method          APD     ADE     FDE     MMADE   MMFDE
#   zero-velocity   0.000   1.2061  1.6766  1.2188  1.6897
#   CVAE, N(0, I)   9.006   1.6678  1.7345  1.6696  1.7346
#   DLow            2.770   1.6627  1.7621  1.6647  1.7638
# Both trained models are worse than standing still here: one short trial is too little to learn from.
# Then `jaxmotion predict runs/dlow_cmu_bvh --input ../shared/data/cmu-bvh/01_03.bvh --out futures/`
# resamples the 120 fps clip to 30 fps and writes BVH futures on the CMU skeleton.
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_cmu_bvh",
        dataset="../shared/data/cmu-bvh",
        data_options={"fps": 30.0},
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=300, batch_size=32, nz=32, nh_rnn=64, nh_mlp=(128,)),
            q=QConfig(num_steps=100, batch_size=16, nh_rnn=64, nh_mlp=(128,)),
        ),
        eval_k=(10,),
        ckpt_every=100,
        log_every=50,
        eval_batch=32,
    )
