"""MMADE / MMFDE's ground truth from four sources (`Config.mm_ground_truth`, protocol §2 (docs/pages/protocol.md#metrics) and its MotionMap option).

The MotionMap sources motion-transfer each member's future onto the window's skeleton before the
min-over-K terms; here that is checked against the same terms computed from explicitly transferred
futures, and a skeleton that every future already has must change nothing.
"""

from __future__ import annotations

import dataclasses
import json

import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.config import Config, validate
from jaxmotion.method import Method
from jaxmotion.eval import reference
from jaxmotion.methods.common import zero_velocity

PARENTS = (-1, 0, 1, 2, 0, 4, 5)  # a root, two chains of three joints


def _fake(rng, n, t, d):
    return rng.normal(scale=0.3, size=(n, t, d)).astype(np.float32)


def _explicit_mm(pred, poses, futures, idx, mask):
    ade, fde = [], []
    for i in range(len(pred)):
        moved = np.asarray(metrics.motion_transfer(jnp.asarray(futures[idx[i][mask[i]]]), jnp.asarray(poses[i]), PARENTS))
        dist = np.linalg.norm(pred[i][:, None] - moved[None], axis=-1)  # (k, m, t)
        ade.append(dist.mean(-1).min(0).mean())
        fde.append(dist[..., -1].min(0).mean())
    return np.array(ade), np.array(fde)


def test_transferred_mm_terms_equal_explicitly_transferred_futures():
    rng = np.random.default_rng(0)
    n, k, t, d = 6, 4, 5, 3 * (len(PARENTS) - 1)
    pred, gt, futures = rng.normal(scale=0.3, size=(n, k, t, d)).astype(np.float32), _fake(rng, n, t, d), _fake(rng, 9, t, d)
    poses = _fake(rng, 1, n, d)[0]
    idx = rng.integers(0, 9, size=(n, 4)).astype(np.int32)
    mask = rng.random((n, 4)) < 0.7
    mask[:, 0] = True
    per = metrics.window_metrics(pred, gt, futures, idx, mask, transfer_poses=poses, transfer_parents=PARENTS)
    ade, fde = _explicit_mm(pred, poses, futures, idx, mask)
    np.testing.assert_allclose(per["MMADE"], ade, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(per["MMFDE"], fde, rtol=1e-4, atol=1e-5)
    a, f = metrics.mm_errors_transferred(pred, poses, futures, idx, mask, PARENTS)
    np.testing.assert_allclose(np.asarray(a), ade, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(np.asarray(f), fde, rtol=1e-4, atol=1e-5)
    # Every future already on one skeleton, and that skeleton as the target: the plain terms.
    same = np.asarray(metrics.motion_transfer(jnp.asarray(futures), jnp.asarray(poses[0]), PARENTS))
    plain = metrics.window_metrics(pred, gt, same, idx, mask)
    moved = metrics.window_metrics(pred, gt, same, idx, mask, transfer_poses=np.repeat(poses[:1], n, 0), transfer_parents=PARENTS)
    np.testing.assert_allclose(moved["MMADE"], plain["MMADE"], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(moved["MMFDE"], plain["MMFDE"], rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="both `transfer_poses` and `transfer_parents`"):
        metrics.window_metrics(pred, gt, futures, idx, mask, transfer_poses=poses)
    with pytest.raises(ValueError, match="transfer_poses"):
        metrics.window_metrics(pred, gt, futures, idx, mask, transfer_poses=np.full_like(poses, np.nan), transfer_parents=PARENTS)


@pytest.fixture
def stub_method(monkeypatch):
    """A method with no stages whose one predictor is zero-velocity, registered for one test only."""
    from jaxmotion import method as method_module
    from jaxmotion.methods import methods

    methods()  # the built-in ones first, so that the stub is only added
    m = Method(name="zero_velocity_stub", config_type=dict, stages=lambda c, p: [],
               predictors=lambda c, ds, params, k: {"zero_velocity": zero_velocity(ds.t_pred, k)})
    monkeypatch.setitem(method_module._REGISTRY, m.name, m)
    return m.name


@pytest.fixture(scope="module")
def prep():
    ds = experiment.load_data(Config())
    return experiment.prepare(ds, 40)


def test_every_source_builds_sets_of_its_candidates(prep):
    n = len(prep.windows)
    test = reference("test").build(prep)
    assert test.futures is None and test.transfer_parents is None
    train = reference("train").build(prep)
    assert train.futures.shape[1:] == prep.y.shape[1:] and int(np.asarray(train.sets.idx).max()) < len(train.futures)
    mt = reference("motionmap-test").build(prep)
    idx, mask = np.asarray(mt.sets.idx), np.asarray(mt.sets.mask)
    assert mt.futures is None and mt.transfer_parents == tuple(prep.dataset.skeleton.parents)
    assert all(i in idx[i][mask[i]] for i in range(n))  # a window is in its own MotionMap set
    mtr = reference("motionmap-train").build(prep)
    assert mtr.futures.shape == train.futures.shape and mtr.transfer_poses.shape == (n, prep.dataset.dim)
    with pytest.raises(ValueError, match="source must be one of"):
        reference("motionmap")


def test_evaluate_records_the_source_and_uses_transferred_futures(prep, tmp_path, stub_method):
    cfg = Config(method=stub_method, method_config={}, eval_k=(2,), max_test_windows=40, mm_ground_truth="motionmap-test",
                 action_metrics=False)
    rec = experiment.evaluate(cfg, prep, {}, tmp_path)[0]
    assert rec["mm_source"] == "motionmap-test" and json.loads((tmp_path / "metrics.json").read_text())[0]["mm_source"] == "motionmap-test"
    ref = reference("motionmap-test").build(prep)
    pred = np.repeat(prep.x[:, -1:][:, None], 2, axis=1).repeat(prep.y.shape[1], axis=2)  # zero velocity, K = 2
    per = metrics.window_metrics(pred, prep.y, prep.y, ref.sets.idx, ref.sets.mask, transfer_poses=ref.transfer_poses,
                                 transfer_parents=ref.transfer_parents)
    assert rec["metrics"]["MMADE"] == pytest.approx(float(per["MMADE"].mean()), rel=1e-5)
    plain = experiment.evaluate(dataclasses.replace(cfg, mm_ground_truth=None), prep, {}, tmp_path)[0]
    assert plain["mm_source"] == "test" and plain["metrics"]["ADE"] == pytest.approx(rec["metrics"]["ADE"], rel=1e-6)


def test_an_unknown_source_is_a_config_error():
    with pytest.raises(Exception, match="mm_ground_truth"):
        validate(Config(mm_ground_truth="motionmap"), 100)
