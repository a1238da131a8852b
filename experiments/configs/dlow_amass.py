# jaxmotion run --config experiments/configs/dlow_amass.py --data amass:/path/to/AMASS --workdir runs/dlow_amass
#
# AMASS is licensed and not shipped: register at amass.is.tue.mpg.de, download the "SMPL-H G"
# archive of every BeLFusion sub-dataset (train ACCAD BMLhandball BMLmovi BMLrub CMU EKUT
# EyesJapanDataset KIT PosePrior TCDHands TotalCapture; test DFaust DanceDB GRAB HUMAN4D SOMA SSM
# Transitions) and extract them into one folder (/path/to/AMASS/CMU/01/01_01_poses.npz, ...).
# The joints need the SMPL-H body model, also licensed: mano.is.tue.mpg.de, Downloads, "Extended
# SMPL+H model" (the one AMASS uses), extracted so that $JAXMOTION_SMPLH (default
# ~/body_models/smplh) holds male/model.npz, female/model.npz, neutral/model.npz.
# Not run here (neither data nor model is available): no runtime or result has been measured.
# The first run computes the joints of every sequence once (cached in ~/.cache/jaxmotion/amass).
"""DLow on AMASS under BeLFusion's protocol (protocol §4 (docs/pages/protocol.md#datasets)): the 22 SMPL-H body joints of the
gendered models, 60 fps (every round(mocap_framerate / 60)-th frame), 30 -> 120 frames, pelvis
dropped (D = 63), MM threshold 0.4; training on BeLFusion's 11 training sub-datasets (add
`"include_validation": True` to `data_options` to train on its 4 validation ones too, as its
released AMASS model did), test windows every 30 frames of the 7 test sub-datasets.

Budget: DLow's released Human3.6M schedule counted in steps (CVAE 500 epochs x 5000 windows /
batch 64; Q network 500 epochs x 1000 windows / batch 32), the paper's loss weights (`CVAEConfig`,
`QConfig` defaults); not tuned for AMASS.
"""
import os

from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig


def get_config() -> Config:
    return Config(
        name="dlow_amass",
        dataset="amass:~/data/AMASS",
        data_options={"protocol": "belfusion", "model_path": os.environ.get("JAXMOTION_SMPLH", "~/body_models/smplh")},
        method_config=DLowConfig(
            cvae=CVAEConfig(num_steps=500 * 5000 // 64, batch_size=64),
            q=QConfig(num_steps=500 * 1000 // 32, batch_size=32),
        ),
        eval_k=(50,),
        ckpt_every=2000,
        log_every=200,
    )
