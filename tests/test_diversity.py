"""The diversity-scale rule (`jaxmotion.diversity`) and the validation split (`jaxmotion.data.validation`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from jaxmotion import diversity
from jaxmotion.eval import metrics
from jaxmotion.config import Config, ConfigError, load_config, validate
from jaxmotion.data.validation import validation_indices, validation_split
from jaxmotion.data.windows import sequence_frames, test_windows
from jaxmotion.experiment import load_data, prepare

CONFIGS = Path(__file__).resolve().parents[1] / "experiments" / "configs"
BANDAI_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def test_rule_relates_the_releases_values():
    # The rule's constants are geometric means over the two releases, so each release sits within
    # the documented factors of the rule and the two factors of one constant multiply to 1.
    f = diversity.release_factors()
    bounds = {"dlow": 1.13, "first": 1.67, "rest": 1.42}
    for k, bound in bounds.items():
        assert math.isclose(f["h36m"][k] * f["humaneva"][k], 1.0, rel_tol=1e-12)
        for r in f.values():
            assert 1 / bound <= r[k] <= bound
    h36m, humaneva = diversity.RELEASES
    # Applied to the releases' documented spreads, the rule orders the datasets as the releases do.
    assert diversity.dlow_d_scale(h36m.spread, h36m.t_pred, h36m.dim) > diversity.dlow_d_scale(humaneva.spread, humaneva.t_pred, humaneva.dim)
    a_h, b_h = diversity.gsps_alphas(h36m.spread, h36m.t_pred, h36m.dim, h36m.coords_first, h36m.coords_rest)
    assert (a_h, b_h) == pytest.approx((60.1, 212.4), abs=0.05)


def test_future_spread_is_the_zero_velocity_ade_and_scales_with_the_data():
    rng = np.random.default_rng(0)
    w = np.cumsum(rng.normal(0, 0.01, (7, 20, 12)), axis=1)
    s = diversity.future_spread(w, t_his=5)
    zero_velocity = np.repeat(w[:, None, 4:5], 15, axis=2)  # (n, 1, t_pred, d)
    assert s == pytest.approx(float(np.mean(metrics.ade(zero_velocity, w[:, 5:]))), rel=1e-5)
    # Twice the motion: twice the spread, alpha and beta twice, d_scale four times.
    s2 = diversity.future_spread(2 * w, t_his=5)
    assert s2 == pytest.approx(2 * s)
    assert diversity.dlow_d_scale(s2, 15, 12) == pytest.approx(4 * diversity.dlow_d_scale(s, 15, 12))
    assert diversity.gsps_alphas(s2, 15, 12, 6, 6) == pytest.approx(tuple(2 * v for v in diversity.gsps_alphas(s, 15, 12, 6, 6)))
    # The L1 scales grow with the number of distances summed.
    a, b = diversity.gsps_alphas(s, 30, 12, 6, 3)
    assert a == pytest.approx(2 * diversity.gsps_alphas(s, 15, 12, 6, 3)[0]) and b / a == pytest.approx(diversity.CONSTANTS["rest"] / (2 * diversity.CONSTANTS["first"]))


def test_future_spread_rejects_bad_windows():
    with pytest.raises(ValueError, match="NaN"):
        diversity.future_spread(np.full((2, 10, 6), np.nan), 5)
    with pytest.raises(ValueError, match="t_his"):
        diversity.future_spread(np.zeros((2, 10, 6)), 10)


def test_validation_indices_take_every_fifth_of_each_action():
    actions = ["walk"] * 10 + ["run"] * 6 + ["wave"]
    names = [f"c{i:02d}" for i in range(17)][::-1]
    held = validation_indices(actions, names)
    by_action = {a: [i for i in held if actions[i] == a] for a in set(actions)}
    assert {a: len(v) for a, v in by_action.items()} == {"walk": 2, "run": 2, "wave": 1}
    walk = sorted(names[i] for i in range(10))
    assert sorted(names[i] for i in by_action["walk"]) == [walk[0], walk[5]]
    with pytest.raises(ValueError, match="every"):
        validation_indices(actions, names, every=1)


def test_validation_split_holds_back_training_sequences_and_drops_the_test_split():
    ds = load_data(Config())
    val = validation_split(ds)
    names = lambda seqs: [s.name for s in seqs]  # noqa: E731
    assert sorted(names(val.train) + names(val.test)) == sorted(names(ds.train))
    assert not set(names(val.test)) & set(names(ds.test))
    assert len(val.test) == math.ceil(len(ds.train) / 5)
    # The synthetic labels follow their sequences: the known modes of the held-back windows are their own futures' modes.
    modes, _, true_mode, _ = val.known_modes(val)
    prep = prepare(val)
    assert modes.shape[0] == prep.windows.shape[0]
    chosen = modes[np.arange(len(true_mode)), true_mode]
    np.testing.assert_allclose(chosen, prep.y, atol=1e-5)


def test_config_split_selects_the_validation_windows():
    cfg = dataclasses.replace(Config(), split="val")
    ds = load_data(cfg)
    assert ds.info["validation"]["every"] == 5 and len(ds.info["validation"]["held_back"]) == len(ds.test)
    with pytest.raises(ConfigError, match="split"):
        validate(dataclasses.replace(Config(), split="validation"))


@pytest.mark.skipif(not BANDAI_DIR.is_dir(), reason=f"Bandai-Namco-2 not found at {BANDAI_DIR}")
def test_gsps_rule_config_holds_the_rule_on_bandai_training_windows():
    ds = load_data(dataclasses.replace(Config(), dataset=str(BANDAI_DIR)))
    windows, _, _ = test_windows(sequence_frames(ds.train), ds.t_his, ds.t_pred)
    s = diversity.future_spread(windows, ds.t_his)
    assert s == pytest.approx(0.466, abs=5e-4)
    c = load_config(CONFIGS / "gsps_bandai_val.py").method_config
    assert (c.alpha, c.beta) == pytest.approx(diversity.gsps_alphas(s, ds.t_pred, ds.dim, 24, 36), abs=0.05)
