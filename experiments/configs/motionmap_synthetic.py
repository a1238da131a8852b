# flock /tmp/jaxmotion-heavy.lock jaxmotion run --config experiments/configs/motionmap_synthetic.py --workdir ~/jaxmotion-runs/motionmap_synthetic
#
# MotionMap (autoencoder -> t-SNE map and codebook -> heatmap -> fine-tune) on the built-in synthetic
# data, K = 6 (the data's number of modes). Training windows: every 15 frames of the 40 training
# sequences (3,000 windows); their MotionMap multimodal ground truth at the dataset's 0.015 m threshold
# (last three observed frames, motion-transferred) is exact here: every member has the same phase and
# current action as its window (checked on seed 0), and a set holds 5.5 of the 6 next actions on average.
# Runtime and result: see experiments/results/motionmap.md.
from jaxmotion.config import Config
from jaxmotion.models.motionmap import MotionMapConfig


def get_config() -> Config:
    return Config(
        name="motionmap_synthetic",
        method="motionmap",
        method_config=MotionMapConfig(ae_steps=2000, hm_steps=1500, ft_steps=500, batch_size=64, hm_size=64),
        eval_k=(6,),
        ckpt_every=500,
    )
