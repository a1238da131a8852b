"""The HumanEva-I configs (`experiments/configs/*_humaneva.py` on `data_3d_humaneva15.npz`) and the test-window count.

Every config loads and builds its method's stages on a fabricated file of HumanEva-I's layout
(VideoPose3D's `positions_3d`: subject -> take -> (T, 15, 3), Train/S1-S3 and Validate/S1-S3, the
releases' dropped takes present); one batch of every trained stage is drawn, nothing is trained.
The test windows follow DLow's `iter_generator(step=15)`: `range(0, T - 75, 15)` per test take
(188 on the real file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jaxmotion import experiment
from jaxmotion.config import load_config, validate
from jaxmotion.data.datasets import load_dataset
from jaxmotion.methods import get_method

CONFIGS = Path(__file__).resolve().parents[1] / "experiments" / "configs"
HUMANEVA_FILE = "data_3d_humaneva15.npz"
# The configs the HumanEva-I table is built from, and each method's stages in order.
EXPECTED = {
    "dlow_humaneva": ("dlow", None), "mojo_vae_dct_humaneva": ("mojo", None), "mojo_vae_dct5_humaneva": ("mojo", None),
    "mojo_vae_dct20_humaneva": ("mojo", None), "divsamp_humaneva": ("divsamp", ["angle_bounds", "cvae", "sampler"]),
    "gsps_humaneva": ("gsps", ["prior", "angle_bounds", "generator"]), "diffusion_humaneva": ("diffusion", ["diffusion"]),
}  # fmt: skip

# Take lengths (frames): the test takes cover no window (75), one (76, 90), two (91) and more; the
# dropped takes (Train/S3 Walking 1 chunk0 and chunk2, Validate/S3 Walking 1 chunk4) are there to be dropped.
LAYOUT = {
    "Train/S1": {"Walking 1 chunk0": 160, "Jog 1 chunk0": 120}, "Train/S2": {"Box 1 chunk0": 140},
    "Train/S3": {"Walking 1 chunk0": 100, "Walking 1 chunk1": 130, "Walking 1 chunk2": 100, "Jog 1 chunk0": 75},
    "Validate/S1": {"Walking 1 chunk0": 75, "Jog 1 chunk0": 76}, "Validate/S2": {"Box 1 chunk0": 90, "Walking 1 chunk0": 91},
    "Validate/S3": {"Walking 1 chunk4": 300, "Box 1 chunk0": 211},
}  # fmt: skip
DROPPED = {("Train/S3", "Walking 1 chunk0"), ("Train/S3", "Walking 1 chunk2"), ("Validate/S3", "Walking 1 chunk4")}


def fabricate(path: Path, seed: int = 0) -> Path:
    """Writes a HumanEva-I-shaped `positions_3d` npz: per subject a random rest pose, per frame a jitter and a drift."""
    rng = np.random.default_rng(seed)
    data = {}
    for s, takes in LAYOUT.items():
        rest = rng.normal(0, 0.3, (15, 3))
        data[s] = {a: (rest + rng.normal(0, 0.02, (t, 15, 3)) + np.linspace(0, 1, t)[:, None, None]).astype(np.float32)
                   for a, t in takes.items()}
    np.savez(path, positions_3d=np.array(data, dtype=object))
    return path


def humaneva_configs() -> list[str]:
    """Returns the names of the configs under experiments/configs that read the HumanEva-I file."""
    return sorted(p.stem for p in CONFIGS.glob("*_humaneva.py") if load_config(p).dataset == HUMANEVA_FILE)


def test_every_method_reporting_humaneva_has_its_config():
    assert humaneva_configs() == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_config_loads_and_builds_its_stages_on_a_humaneva_shaped_file(name, tmp_path):
    cfg = load_config(CONFIGS / f"{name}.py")
    method, stage_names = EXPECTED[name]
    assert (cfg.name, cfg.method, cfg.dataset, cfg.eval_k) == (name, method, HUMANEVA_FILE, (50,))
    ds = load_dataset(fabricate(tmp_path / HUMANEVA_FILE))
    assert (ds.name, ds.t_his, ds.t_pred, ds.fps, ds.dim) == ("humaneva", 15, 60, 60, 42)
    prep = experiment.prepare(ds, train_sampler=cfg.train_sampler)
    # As `jaxmotion run` checks it against the training windows (GSPS's prior batch of 4,096 single frames
    # is larger than the file's windows, the real file's 2,595 included).
    validate(cfg, prep.sampler.num_windows)
    stages = get_method(method).stages(cfg, prep)
    if stage_names is not None:
        assert [s.name for s in stages] == stage_names
    trained = [s for s in stages if s.num_steps > 0]
    assert trained and all(s.batches is not None for s in trained)
    for s in trained:
        batch = s.batches(np.random.default_rng(0))
        arrays = list(batch.values()) if isinstance(batch, dict) else [batch]
        assert all(np.all(np.isfinite(a)) for a in arrays)
        assert arrays[0].shape[-1] == ds.dim


def test_test_windows_follow_dlows_iter_generator(tmp_path):
    ds = load_dataset(fabricate(tmp_path / HUMANEVA_FILE))
    prep = experiment.prepare(ds)
    # DLow's `iter_generator(step=15)`: starts range(0, T - t_total, 15) of every kept test take.
    expected = [(f"{s}/{a}", i) for s, takes in LAYOUT.items() if s.startswith("Validate/") for a, t in sorted(takes.items())
                if (s, a) not in DROPPED for i in range(0, t - 75, 15)]
    assert len(prep.windows) == len(expected) == 0 + 1 + 1 + 2 + 10
    got = sorted((ds.test[i].name, int(st)) for i, st in zip(prep.seq_index, prep.starts))
    assert got == sorted(expected)
    # Each window is its take's frames from its start.
    for w, i, st in zip(prep.windows, prep.seq_index, prep.starts):
        np.testing.assert_allclose(w[:, :3], ds.test[i].positions[st : st + 75, 1] - ds.test[i].positions[st : st + 75, 0],
                                   atol=1e-6)


def test_budget_fraction_scales_the_methods_steps_and_nothing_else(tmp_path):
    """The stand-in configs' helper: the method's `num_steps` scaled and rounded, a stage's own steps (GSPS's
    prior) and the fraction-of-run schedule kept, the changes applied; a fraction outside (0, 1] is a clear error."""
    import dataclasses

    from jaxmotion.config import budget_fraction
    from jaxmotion.errors import ConfigError

    base = load_config(CONFIGS / "gsps_humaneva.py")
    got = budget_fraction(CONFIGS / "gsps_humaneva.py", 0.1, name="tenth", curve_every=625)
    assert got.method_config.num_steps == round(base.method_config.num_steps * 0.1) == 6250
    assert got.method_config.prior_num_steps == base.method_config.prior_num_steps
    assert got.name == "tenth" and got.curve_every == 625
    want = dataclasses.replace(base, name="tenth", curve_every=625,
                               method_config=dataclasses.replace(base.method_config, num_steps=6250))
    assert got == want
    assert load_config(CONFIGS / "gsps_humaneva_10pct.py").method_config.num_steps == 6250
    assert load_config(CONFIGS / "diffusion_humaneva_5pct.py").method_config.num_steps == 19564
    for bad in (0.0, 1.5):
        with pytest.raises(ConfigError, match=rf"fraction must be in \(0, 1\], got {bad}"):
            budget_fraction(CONFIGS / "gsps_humaneva.py", bad)
