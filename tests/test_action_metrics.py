"""CMD and FID (`jaxmotion.eval.action_metrics`): the definitions on fabricated data, the classifier, and evaluation records."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxmotion.eval import action_metrics as am
from jaxmotion import experiment as ex
from jaxmotion.config import Config
from jaxmotion.data.synthetic import make_synthetic
from jaxmotion.data.types import MotionDataset, Sequence, Skeleton
from jaxmotion.method import Method, register
from jaxmotion.models import action_classifier as ac
from jaxmotion.train.action_classifier import train as train_classifier

SKELETON = Skeleton(("root", "a", "b"), (-1, 0, 0))


def _moving(rng, n_frames: int, speed: float) -> np.ndarray:
    """Returns `(n_frames, 3, 3)` positions: the root still, two points moving `speed` m per frame in fixed directions."""
    direction = rng.normal(size=(2, 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    pos = np.zeros((n_frames, 3, 3))
    pos[:, 1:] = rng.normal(size=(1, 2, 3)) + speed * np.arange(n_frames)[:, None, None] * direction
    return pos


def _labelled_dataset(speeds: dict[str, float], n_train: int = 3, n_test: int = 2, n_frames: int = 40) -> MotionDataset:
    rng = np.random.default_rng(0)
    split = lambda n: [Sequence(_moving(rng, n_frames, v), 10.0, "s", c, f"{c}{i}") for c, v in speeds.items() for i in range(n)]  # noqa: E731
    return MotionDataset("toy", SKELETON, 10.0, 5, 10, 0.5, split(n_train), split(n_test), info={"action_labels": True})


# --------------------------------------------------------------------------------------------
# CMD.


def test_class_cmd_weights_early_frames_most():
    # T = 4: weights 3, 2, 1 on |M_t - Mbar| = 1, 0, 1.
    assert am.class_cmd(np.array([1.0, 2.0, 3.0]), 2.0) == pytest.approx(4.0)


def test_reference_displacement_is_each_class_training_speed():
    ds = _labelled_dataset({"slow": 0.01, "fast": 0.05})
    ref = am.reference_displacement(ds)
    assert ref == pytest.approx({"slow": 0.01, "fast": 0.05}, rel=1e-5)


def test_cmd_is_zero_at_the_class_profile_and_grows_with_more_or_less_motion():
    speeds = {"slow": 0.01, "fast": 0.05}
    ds = _labelled_dataset(speeds)
    ref = am.reference_displacement(ds)
    rng = np.random.default_rng(1)
    labels = np.array(["slow", "slow", "fast"])
    t_pred, big_t = ds.t_pred, ds.t_pred

    def profiles(scale):
        # 3 windows x K = 4 samples, each moving at `scale` times its class's training speed.
        pred = np.stack([np.stack([_moving(rng, t_pred, scale * speeds[c])[:, 1:].reshape(t_pred, 6) for _ in range(4)])
                         for c in labels])  # fmt: skip
        return am.displacement_profile(pred).mean(axis=1)

    assert am.cmd(profiles(1.0), labels, ref) == pytest.approx(0.0, abs=1e-5)
    # |M_t - Mbar_c| = |s - 1| Mbar_c at every t: CMD = sum_c w_c |s - 1| Mbar_c T (T - 1) / 2.
    mean_ref = (2 * speeds["slow"] + speeds["fast"]) / 3
    for scale in (0.5, 2.0, 3.0):
        want = abs(scale - 1) * mean_ref * big_t * (big_t - 1) / 2
        assert am.cmd(profiles(scale), labels, ref) == pytest.approx(want, rel=1e-4)
    assert am.cmd(profiles(3.0), labels, ref) > am.cmd(profiles(2.0), labels, ref) > 0
    with pytest.raises(ValueError, match=r"no reference displacement for classes \['other'\]"):
        am.cmd(profiles(1.0), np.array(["slow", "other", "fast"]), ref)


def test_the_fused_chunk_profile_is_the_mean_displacement_profile():
    pred = np.random.default_rng(0).normal(size=(3, 4, 7, 6)).astype(np.float32)
    np.testing.assert_allclose(np.asarray(am._mean_profile(pred)), am.displacement_profile(pred).mean(axis=1), rtol=1e-5)


def test_window_labels():
    ds = _labelled_dataset({"slow": 0.01, "fast": 0.05})
    assert list(am.window_labels(ds, np.array([0, 3]), np.array([0, 5]), "train")) == ["slow", "fast"]
    assert am.window_labels(dataclasses.replace(ds, info={}), np.array([0]), np.array([0])) is None
    syn = make_synthetic(0, num_train_subjects=1, train_sequences=1, train_segments=4, num_test_subjects=1,
                         test_sequences=1, test_segments=3)  # fmt: skip
    names, seg = syn.info["mode_names"], syn.info["test_segments"][0]
    # Future frames start + 15 .. start + 74 over 60-frame segments: the majority segment, the later one on a tie.
    got = am.window_labels(syn, np.zeros(4, int), np.array([0, 15, 30, 45]))
    assert list(got) == [names[seg[0]], names[seg[1]], names[seg[1]], names[seg[1]]]
    got = am.window_labels(syn, np.zeros(2, int), np.array([60, 75]))
    assert list(got) == [names[seg[1]], names[seg[2]]]


# --------------------------------------------------------------------------------------------
# FID.


def _random_cov(rng, f):
    a = rng.normal(size=(f, f))
    return a @ a.T / f + 0.1 * np.eye(f)


def test_frechet_distance_of_identical_sets_is_zero():
    x = np.random.default_rng(0).normal(size=(500, 6))
    assert am.fid(x, x) == pytest.approx(0.0, abs=1e-8)


def test_frechet_distance_matches_closed_forms():
    rng = np.random.default_rng(0)
    # 2-D: Tr sqrt(M) = sqrt(Tr M + 2 sqrt(det M)) for a 2 x 2 matrix M with positive eigenvalues.
    mu1, mu2 = np.array([0.3, -1.0]), np.array([1.0, 0.5])
    s1, s2 = _random_cov(rng, 2), _random_cov(rng, 2)
    m = s1 @ s2
    want = np.sum((mu1 - mu2) ** 2) + np.trace(s1) + np.trace(s2) - 2 * np.sqrt(np.trace(m) + 2 * np.sqrt(np.linalg.det(m)))
    assert am.frechet_distance(mu1, s1, mu2, s2) == pytest.approx(want, rel=1e-10)
    # Commuting (diagonal) covariances: ||mu1 - mu2||^2 + sum (sqrt a - sqrt b)^2.
    a, b = rng.uniform(0.1, 2, 5), rng.uniform(0.1, 2, 5)
    want = np.sum((np.sqrt(a) - np.sqrt(b)) ** 2) + 4.0
    assert am.frechet_distance(np.zeros(5), np.diag(a), np.full(5, 2 / np.sqrt(5)), np.diag(b)) == pytest.approx(want, rel=1e-10)
    # 8-D against scipy's sqrtm of the (non-symmetric) product, the usual FID code path.
    s1, s2, mu1, mu2 = _random_cov(rng, 8), _random_cov(rng, 8), rng.normal(size=8), rng.normal(size=8)
    want = np.sum((mu1 - mu2) ** 2) + np.trace(s1 + s2) - 2 * np.trace(scipy.linalg.sqrtm(s1 @ s2).real)
    got = am.frechet_distance(mu1, s1, mu2, s2)
    assert got == pytest.approx(want, rel=1e-8)
    assert am.frechet_distance(mu2, s2, mu1, s1) == pytest.approx(got, rel=1e-10)
    # Samples of two Gaussians: the fitted distance converges to the closed form.
    x = rng.multivariate_normal(mu1, s1, size=100_000)
    y = rng.multivariate_normal(mu2, s2, size=100_000)
    assert am.fid(x, y) == pytest.approx(want, rel=0.03)
    assert am.fid(y, x) == pytest.approx(am.fid(x, y), rel=1e-9)


def test_moments_accumulate_like_the_whole_set():
    x = np.random.default_rng(0).normal(size=(50, 4)) + 3.0
    m = am.add_moments(am.moments(x[:20]), am.moments(x[20:]))
    mu, cov = am.mean_cov(m)
    np.testing.assert_allclose(mu, x.mean(0), rtol=1e-12)
    np.testing.assert_allclose(cov, np.cov(x, rowvar=False), rtol=1e-10)


def test_fid_rejects_mismatched_features():
    x = np.zeros((10, 3))
    with pytest.raises(ValueError, match="same f"):
        am.fid(x, np.zeros((10, 4)))
    with pytest.raises(ValueError, match="feature dimensions differ"):
        am.frechet_distance(np.zeros(3), np.eye(3), np.zeros(4), np.eye(4))
    with pytest.raises(ValueError, match="feature dimensions differ"):
        am.add_moments(am.moments(x), am.moments(np.zeros((10, 4))))
    with pytest.raises(ValueError, match="not positive semi-definite"):
        am.frechet_distance(np.zeros(2), np.diag([1.0, -1.0]), np.zeros(2), np.eye(2))


# --------------------------------------------------------------------------------------------
# The classifier.


def test_classifier_tells_still_from_moving_in_a_few_dozen_steps():
    def batch(rng, n=32):
        # 12 frames of 2 points: class 0 stands still at a random pose, class 1 moves 0.2 per frame and axis (sd).
        labels = rng.integers(0, 2, n)
        pose = 0.3 * rng.normal(size=(n, 1, 6))
        vel = 0.2 * rng.normal(size=(n, 1, 6)) * labels[:, None, None]
        return (pose + vel * np.arange(12)[None, :, None]).astype(np.float32), labels

    c = ac.ClassifierConfig(hidden=16, features=8, num_steps=40, batch_size=32, lr=3e-2)
    params = train_classifier(batch, 2, c, log=None)
    model = ac.make_model(2, c)
    y, labels = batch(np.random.default_rng(100), 200)
    assert ac.accuracy(model, params, y, labels) > 0.9
    # Deterministic features: zero initial state, no dropout.
    f1, f2 = ac.predict(model, params, y)[1], ac.predict(model, params, y[:50])[1]
    np.testing.assert_array_equal(f1[:50], f2)
    # `predict` runs the GRU loop unrolled: the features of the rolled loop, to float32 rounding.
    np.testing.assert_allclose(f1, np.asarray(model.apply(params, jnp.asarray(y))[1]), rtol=1e-5, atol=1e-6)
    assert f1.shape == (200, 8) and np.all(np.abs(f1) < 1)


# --------------------------------------------------------------------------------------------
# Evaluation records.


def _predictors(cfg, ds, params, k):
    def still(x, key):
        return jnp.broadcast_to(x[:, None, -1:], (x.shape[0], k, ds.t_pred, x.shape[-1]))

    def jitter(x, key):
        return still(x, key) + 0.05 * jax.random.normal(key, (x.shape[0], k, ds.t_pred, x.shape[-1]))

    return {"zero_velocity": jax.jit(still), "jitter": jax.jit(jitter)}


register(Method(name="action_metrics_test", config_type=dict, stages=lambda cfg, prep: [], predictors=_predictors), replace=True)
# The same, with zero-velocity scored on all K of its copies rather than on one (`Method.deterministic`).
register(Method(name="action_metrics_test_all_copies", config_type=dict, stages=lambda cfg, prep: [], predictors=_predictors,
                deterministic=()), replace=True)


def test_evaluate_writes_cmd_and_fid_where_the_dataset_has_labels(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cfg = Config(method="action_metrics_test", method_config={}, eval_k=(2,), max_test_windows=40, eval_batch=16,
                 action_classifier_steps=30)  # fmt: skip
    prep = ex.prepare(ex.load_data(cfg), cfg.max_test_windows)
    ex.evaluate(cfg, prep, {}, tmp_path / "a")
    out = capsys.readouterr().out
    assert "action classifier (synthetic): training on" in out and "test accuracy" in out
    written = json.loads((tmp_path / "a" / "metrics.json").read_text())
    m = {r["method"]: r["metrics"] for r in written}
    assert set(m) == {"zero_velocity", "jitter"}
    for r in written:
        assert np.isfinite(r["metrics"]["CMD"]) and np.isfinite(r["metrics"]["FID"]) and r["metrics"]["FID"] >= 0
        assert r["config"]["action_classifier"]["num_steps"] == 30
        assert 0 <= r["config"]["action_classifier"]["accuracy"] <= 1
    # Standing still: every M_t is 0, so CMD is the windows' mean Mbar_c times T (T - 1) / 2 exactly.
    ds = prep.dataset
    labels = am.window_labels(ds, prep.seq_index, prep.starts)
    ref = am.reference_displacement(ds)
    want = np.mean([ref[c] for c in labels]) * ds.t_pred * (ds.t_pred - 1) / 2
    assert m["zero_velocity"]["CMD"] == pytest.approx(want, rel=1e-6)
    assert m["jitter"]["FID"] != m["zero_velocity"]["FID"]
    cached = list((tmp_path / "cache" / "jaxmotion" / "action_classifiers").glob("synthetic_*"))
    assert sorted(p.suffix for p in cached) == [".json", ".msgpack"]
    info = json.loads(next(p for p in cached if p.suffix == ".json").read_text())
    assert info["num_classes"] == 6 and info["num_steps"] == 30 and info["seed"] == 0 and "not BeLFusion" in info["note"]
    assert info["accuracy"] == written[0]["config"]["action_classifier"]["accuracy"]

    # Asked again, the classifier is loaded from the cache, not trained, and reproduces the record.
    again = am.dataset_classifier(ds, ac.ClassifierConfig(num_steps=30))
    assert "cached" in capsys.readouterr().out
    ev = am.ActionEvaluator(again, prep.y, labels, ref, batch=16)
    still = np.broadcast_to(prep.x[:, None, -1:], (len(prep.x), 2, ds.t_pred, ds.dim))  # the zero_velocity predictor, K = 2
    got = ev.result([ev.chunk(still[s : s + 16]) for s in range(0, len(still), 16)])
    assert got == pytest.approx({k: m["zero_velocity"][k] for k in ("CMD", "FID")}, rel=1e-5)

    # A dataset without labels: the keys are absent, not NaN.
    unlabelled = dataclasses.replace(prep, dataset=dataclasses.replace(ds, info={**ds.info, "action_labels": False}))
    for r in ex.evaluate(cfg, unlabelled, {}, tmp_path / "c"):
        assert "CMD" not in r["metrics"] and "FID" not in r["metrics"] and "action_classifier" not in r["config"]


def test_a_deterministic_predictor_scored_on_one_copy_gets_the_metrics_of_all_k(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    cfg = Config(method="action_metrics_test", method_config={}, eval_k=(3,), max_test_windows=40, eval_batch=16,
                 action_classifier_steps=30)  # fmt: skip
    prep = ex.prepare(ex.load_data(cfg), cfg.max_test_windows)
    one = {r["method"]: r["metrics"] for r in ex.evaluate(cfg, prep, {}, tmp_path / "one")}
    every = {r["method"]: r["metrics"] for r in ex.evaluate(
        dataclasses.replace(cfg, method="action_metrics_test_all_copies"), prep, {}, tmp_path / "all")}
    assert one["zero_velocity"]["APD"] == every["zero_velocity"]["APD"] == 0
    # ADE ... MMFDE, their medians, mode recall (the synthetic data knows its modes), CMD and FID.
    assert {"mode_recall", "CMD", "FID", "MMADE"} <= set(one["zero_velocity"])
    assert one["zero_velocity"] == pytest.approx(every["zero_velocity"], rel=1e-5, abs=1e-7)
    assert one["jitter"] == every["jitter"]  # a random predictor is scored on every sample either way
