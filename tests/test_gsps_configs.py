"""GSPS's Human3.6M and HumanEva-I configs: the release's budgets, and the method's stages built on fabricated files.

The files have the real layout (VideoPose3D's `positions_3d` dict of subject -> action -> (T, J, 3),
32 joints for Human3.6M, 15 for HumanEva-I) with random poses; nothing is trained.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

from jaxmotion import experiment
from jaxmotion.config import load_config
from jaxmotion.data.datasets import load_dataset
from jaxmotion.methods import get_method
from jaxmotion.models import gsps

CONFIGS = Path(__file__).resolve().parents[1] / "experiments" / "configs"


def fabricate(path: Path, subjects: dict[str, dict[str, int]], num_joints: int, seed: int = 0) -> Path:
    """Writes a `positions_3d` npz: per subject a random rest pose, per frame a small jitter and a drift."""
    rng = np.random.default_rng(seed)
    data = {}
    for s, acts in subjects.items():
        rest = rng.normal(0, 0.3, (num_joints, 3))
        data[s] = {a: (rest + rng.normal(0, 0.02, (t, num_joints, 3)) + np.linspace(0, 1, t)[:, None, None]).astype(np.float32)
                   for a, t in acts.items()}
    np.savez(path, positions_3d=np.array(data, dtype=object))
    return path


H36M = {s: {"Walking": 150, "Eating": 140} for s in ("S1", "S5", "S6", "S7", "S8", "S9", "S11")}
HUMANEVA = {s: {"Walking 1 chunk1": 110, "Jog 1 chunk0": 100}
            for s in ("Train/S1", "Train/S2", "Train/S3", "Validate/S1", "Validate/S2", "Validate/S3")}

# name, file, layout, joints, budget (prior steps, generator steps), n_pre, (div first, div rest, alpha, beta),
# pseudo ground truth (candidate stride, future threshold), the release's `parts` (root-dropped joint indices).
CASES = [
    ("gsps_h36m", "data_3d_h36m.npz", H36M, 32, (1220, 156_250), 10, (8.0, 25.0, 100.0, 300.0), (20, 0.1),
     ((0, 1, 2, 3, 4, 5), (6, 7, 8, 9, 10, 11, 12, 13, 14, 15))),
    ("gsps_humaneva", "data_3d_humaneva15.npz", HUMANEVA, 15, (1200, 62_500), 8, (5.0, 10.0, 15.0, 50.0), (15, 0.01),
     ((7, 8, 9, 10, 11, 12), (0, 1, 2, 3, 4, 5, 6, 13))),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_config_has_the_release_settings_and_builds_the_stages(case, tmp_path):
    name, file, layout, joints, (prior_steps, gen_steps), n_pre, div, (stride, pred_thr), release_parts = case
    cfg = load_config(CONFIGS / f"{name}.py")
    c = cfg.method_config
    assert (cfg.name, cfg.method, cfg.dataset, cfg.eval_k) == (name, "gsps", file, (50,))
    assert isinstance(c, gsps.GSPSConfig) and gsps.check_config(c) is c
    # The prior: 3 layers, 25 epochs x 200k frames at batch 4096, 5 of them at constant lr 1e-2.
    assert (c.prior_layers, c.prior_lr, c.prior_weight_decay, c.prior_batch_size) == (3, 1e-2, 1e-3, 4096)
    assert (c.prior_num_steps, c.prior_lr_fix_fraction) == (prior_steps, 0.2)
    # The generator: 500 epochs at batch 16, 100 constant; 10 x 10 samples; the dataset's DCT length and diversity.
    assert (c.num_steps, c.batch_size, c.lr, c.lr_fix_fraction, c.grad_clip) == (gen_steps, 16, 1e-3, 0.2, 100.0)
    assert (c.hidden, c.num_stage, c.nz, c.nk1, c.nk2, c.n_pre, c.parts) == (256, 4, 64, 10, 10, n_pre, "lower_upper")
    assert (c.lambda_div_first, c.lambda_div_rest, c.alpha, c.beta) == div
    assert (c.lambda_his, c.lambda_limb, c.lambda_recon, c.lambda_recon_mm, c.lambda_prior, c.lambda_angle) == (
        100.0, 500.0, 2.0, 1.0, 0.01, 100.0)
    assert (c.mm_candidate_stride, c.mm_pred_threshold) == (stride, pred_thr)

    ds = load_dataset(fabricate(tmp_path / file, layout, joints))
    # The lower / upper split found from joint names is the release's `parts` for this skeleton.
    assert gsps.body_parts(tuple(ds.skeleton.names), tuple(ds.skeleton.parents), c.parts) == release_parts
    prep = experiment.prepare(ds)
    stages = get_method("gsps").stages(cfg, prep)
    assert [s.name for s in stages] == ["prior", "angle_bounds", "generator"]
    assert [s.num_steps for s in stages] == [prior_steps, 0, gen_steps]
    assert stages[2].frozen == ("prior", "angle_bounds") and stages[2].batch_norm
    # One batch of each trained stage, at the release's sizes.
    frames = stages[0].batches(np.random.default_rng(0))
    assert frames.shape == (4096, ds.dim)
    batch = stages[2].batches(np.random.default_rng(0))
    assert batch["window"].shape == (16, ds.t_total, ds.dim)
    assert batch["mm"].shape == (16, c.mm_num, ds.t_pred, ds.dim) and batch["mm_mask"].shape == (16, c.mm_num)
    # Parameter shapes of both networks (traced, not computed): a flow on the limb directions, GCNs on
    # 3 n_pre DCT coefficients per joint plus the 64-d noise.
    prior = jax.eval_shape(lambda: stages[0].init(jax.random.key(0), {}))
    assert prior["params"]["linqr_0"]["r"].shape == (ds.dim, ds.dim)
    gen = jax.eval_shape(lambda: stages[2].init(jax.random.key(0), {}))
    assert set(gen["params"]) == {"part_0", "part_1"}
    assert gen["params"]["part_0"]["gcn"]["gcl_in"]["gc"]["kernel"].shape == (3 * n_pre + 64, 256)
    assert gen["params"]["part_1"]["out"]["adjacency"].shape == (ds.dim // 3, ds.dim // 3)
