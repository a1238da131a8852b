# jaxmotion run --config experiments/configs/diffusion_humaneva.py --data /path/to/data_3d_humaneva15.npz --workdir ~/jaxmotion-runs/humaneva/diffusion_humaneva_s0 --seed 0 [--resume]
# python experiments/plot_curves.py ~/jaxmotion-runs/humaneva/diffusion_humaneva_s0
# The paper's row (HumanMAC, ICCV 2023, Table 1, HumanEva-I, K = 50; arXiv 2302.03665):
# APD 6.554, ADE 0.209, FDE 0.223, MMADE 0.342, MMFDE 0.320. Read from a later paper's HumanEva-I comparison
# table that quotes HumanMAC's row (the same five numbers, beside DLow's and DivSamp's rows as this library
# quotes them); the stored copies of HumanMAC's paper reachable here showed its text, not Table 1.
# Release budget: 501 epochs x 781 batches of 64 (50,000 // 64): 391,281 steps, 25.0M windows.
# Measured here (2-core Intel Xeon, family 6 model 167, AVX-512/AMX, 2.6 GHz, the cores shared with another
# training run, load average 5.5, so upper bounds): 1.08 s/step (steps 2-8 of a tiny-budget copy of this
# config), 117 h for the full budget on this CPU; K = 50 futures of the 188 test windows took 433 s at 10
# DDIM steps, so about 72 min at the release's 100.
"""The diffusion predictor on HumanEva-I (15 -> 60 frames at 60 fps, 14 joints) at HumanMAC's release settings.

Read against `cfg/humaneva.yml` and the code of github.com/LinghaoChan/HumanMAC:
- Denoiser (`utils/script.py` `create_model_and_diffusion`, `models/transformer.py`): `n_pre` 10 DCT
  coefficients of the 75-frame window, 4 blocks (`num_layers`), 8 heads, width 512 (`latent_dims`),
  feed-forward 1024 (`MotionTransformer`'s `ff_size` default), dropout 0.2, the condition the DCT of the
  history padded with its last frame (`padding: 'LastFrame'`).
- Diffusion (`models/diffusion.py`): 1000 noise steps on the cosine schedule, training timesteps drawn
  in 1..999, 100 DDIM steps (`ddim_timesteps`) at `range(0, 1000, 10) + 1`, DCT completion on
  (`Complete: True`).
- Training (`utils/training.py`, `main.py`): Adam lr 3e-4, batch 64, 501 epochs of `num_data_sample`
  50,000 windows (781 batches), `MultiStepLR` x0.9 at epochs 75, 150, 225, 275, 350, 450
  (`lr_milestones`), EMA 0.995 after 2,000 steps (`EMA.step_ema`). The condition is always kept in
  training (`mod_train: 1.`: `cond_drop` 0; the release draws it per batch, the library per window,
  the same here). Data: a subject uniformly, then a take, then a start (`data_loader/dataset.py`
  `sample`; `train_sampler="subjects"`).
- Evaluation (`utils/evaluation.py` `compute_stats`, `utils/script.py` `sample_preprocessing`): K = 50
  passes over the test windows, each conditioned with probability `mod_test` 0.5 and otherwise denoised
  without the condition, DCT completion alone tying it to the history (`test_cond_keep` 0.5);
  windows every 15 frames (`iter_generator(step=cfg.t_his)`: DLow's 188) and MM threshold 0.5
  (`--multimodal_threshold`).
Learning curves every 25,000 steps on the test windows (K = 50), read only for plotting.
"""
from jaxmotion.config import Config
from jaxmotion.models.diffusion import DiffusionConfig

EPOCHS = 501
MILESTONES = (75, 150, 225, 275, 350, 450)  # epochs


def get_config() -> Config:
    return Config(
        name="diffusion_humaneva",
        method="diffusion",
        dataset="data_3d_humaneva15.npz",
        train_sampler="subjects",
        eval_k=(50,),
        ckpt_every=5000,
        log_every=500,
        curve_every=25000,
        method_config=DiffusionConfig(
            n_dct=10, latent=512, ff=1024, num_layers=4, num_heads=8, dropout=0.2, noise_steps=1000,
            schedule="cosine", sampling_steps=100, cond_drop=0.0, test_cond_keep=0.5, ema_decay=0.995,
            ema_start=2000, lr=3e-4, batch_size=64, num_steps=EPOCHS * (50_000 // 64),
            lr_milestones=tuple(m / EPOCHS for m in MILESTONES), lr_gamma=0.9,
        ),
    )
