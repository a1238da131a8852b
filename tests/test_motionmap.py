"""MotionMap: motion transfer, MotionMap's multimodal ground truth, maps, codebook, peaks, NLL, stages."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion.eval import metrics
from jaxmotion.data.synthetic import PARENTS
from jaxmotion.models import motionmap as mm

FP = mm.frame_parents(PARENTS)


def _links(frames: np.ndarray) -> np.ndarray:
    """(..., D) -> (..., J-1, 3) link vectors child - parent (parent the origin for the root's children)."""
    p = frames.reshape(frames.shape[:-1] + (-1, 3))
    par = np.stack([p[..., q, :] if q >= 0 else np.zeros_like(p[..., 0, :]) for q in FP], axis=-2)
    return p - par


def test_motion_transfer_keeps_target_bone_lengths_and_source_directions():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(4, 7, 48)).astype(np.float32)
    tgt = rng.normal(size=(4, 1, 48)).astype(np.float32)
    out = np.asarray(mm.motion_transfer(jnp.asarray(src), jnp.asarray(tgt), PARENTS))
    assert out.shape == (4, 7, 48)
    lo, ls, lt = _links(out), _links(src), _links(tgt)
    np.testing.assert_allclose(np.linalg.norm(lo, axis=-1), np.broadcast_to(np.linalg.norm(lt, axis=-1), (4, 7, 16)), rtol=1e-5)
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)
    np.testing.assert_allclose(unit(lo), unit(ls), atol=1e-5)
    # A skeleton transferred onto itself is unchanged.
    np.testing.assert_allclose(np.asarray(mm.motion_transfer(jnp.asarray(src), jnp.asarray(src), PARENTS)), src, atol=1e-5)


def test_motion_transfer_rejects_a_skeleton_without_parents_first():
    with pytest.raises(ValueError, match="parent before its child"):
        mm.frame_parents((-1, 2, 0))


def test_motionmap_mm_sets_match_brute_force_and_include_self():
    rng = np.random.default_rng(1)
    base = rng.normal(size=(3, 3, 48)).astype(np.float32) * 0.3
    desc = np.concatenate([base + 0.002 * rng.normal(size=base.shape) for _ in range(4)]).astype(np.float32)
    thr = 0.05
    sets = metrics.motionmap_mm_sets(desc, thr, PARENTS, max_chunk_elems=1000)  # many small chunks
    idx, mask = np.asarray(sets.idx), np.asarray(sets.mask)
    for i in range(len(desc)):
        moved = np.asarray(mm.motion_transfer(jnp.asarray(desc), jnp.asarray(desc[i, -1]), PARENTS))
        d = np.linalg.norm((moved - desc[i]).reshape(len(desc), -1), axis=-1)
        want = set(np.nonzero(d < thr)[0]) | {i}
        assert set(idx[i, mask[i]]) == want
    # Transfer makes a rescaled copy of a motion a neighbour, where plain distance would not
    # (each descriptor made one skeleton over its frames first, as real motion is).
    one = np.asarray(mm.motion_transfer(jnp.asarray(desc), jnp.asarray(desc[:, -1:]), PARENTS))
    ref = one * 1.2
    desc = one
    r = metrics.motionmap_mm_sets(desc[:3], thr, PARENTS, reference_desc=ref)
    assert all(i in set(np.asarray(r.idx)[i, np.asarray(r.mask)[i]]) for i in range(3))


@pytest.mark.parametrize("band", [0.0, 1.0, None])
def test_motionmap_mm_sets_decide_pairs_at_the_threshold_as_the_definition(monkeypatch, band):
    # References placed at 1 -+ 1e-5 of the threshold from their query, after transfer: the float64 product
    # alone (band 0), the float32 definition alone (band 1: every pair rechecked) and the default agree with
    # the definition computed pair by pair.
    if band is not None:
        monkeypatch.setattr(metrics, "MM_BAND", band)
    rng = np.random.default_rng(3)
    desc = rng.normal(size=(12, 3, 48)).astype(np.float32) * 0.3
    desc = np.asarray(mm.motion_transfer(jnp.asarray(desc), jnp.asarray(desc[:, -1:]), PARENTS))  # one skeleton each
    thr = 0.2
    refs, want = [], {i: set() for i in range(len(desc))}
    for i in range(len(desc)):
        for sign in (-1.0, 1.0):
            step = 0.02 * rng.normal(size=desc[i].shape)
            for _ in range(40):  # scale the step until the transferred distance sits at the wanted ratio
                cand = (desc[i] + step).astype(np.float32)
                moved = np.asarray(mm.motion_transfer(jnp.asarray(cand), jnp.asarray(desc[i, -1:]), PARENTS))
                step = step * thr * (1 + sign * 1e-5) / np.linalg.norm(moved - desc[i])
            refs.append(cand)
    refs = np.stack(refs + list(rng.normal(size=(20, 3, 48)).astype(np.float32) * 0.3))
    for i in range(len(desc)):
        moved = np.asarray(mm.motion_transfer(jnp.asarray(refs), jnp.asarray(desc[i, -1:]), PARENTS))
        d = np.linalg.norm((moved - desc[i]).reshape(len(refs), -1), axis=-1)
        want[i] = set(np.nonzero(d < thr)[0])
        assert {2 * i} <= want[i] and 2 * i + 1 not in want[i]  # the construction: one just inside, one just outside
    sets = metrics.motionmap_mm_sets(desc, thr, PARENTS, reference_desc=refs, max_chunk_elems=100)
    idx, mask = np.asarray(sets.idx), np.asarray(sets.mask)
    assert all(set(idx[i, mask[i]]) == want[i] for i in range(len(desc)))


def test_gaussian_heatmap_has_its_maxima_at_the_cells():
    cells = jnp.array([[5.0, 7.0], [20.0, 3.0], [12.0, 25.0], [0.0, 0.0]])
    mask = jnp.array([True, True, True, False])
    hm = np.asarray(mm.gaussian_heatmap(cells, mask, 32, 2.0))
    for r, c in np.asarray(cells[:3]).astype(int):
        assert hm[r, c] == pytest.approx(1.0)
        assert hm[r, c] >= hm[max(r - 3, 0) : r + 4, max(c - 3, 0) : c + 4].max()
    assert hm[0, 0] < 1e-3  # the masked cell draws nothing
    peaks = mm.find_peaks(jnp.asarray(hm)[None], min_distance=2, threshold_rel=0.5, max_peaks=10)
    got = {tuple(x) for x, v in zip(np.asarray(peaks.cells[0]), np.asarray(peaks.valid[0])) if v}
    assert got == {(5, 7), (20, 3), (12, 25)}


def test_gaussian_heatmap_is_the_max_of_the_two_dimensional_bumps():
    # The map is built from separable 1-D factors; this is the definition it must equal.
    rng = np.random.default_rng(0)
    cells = rng.integers(0, 24, (9, 2)).astype(np.float32)
    mask = np.arange(9) < 7
    u = np.arange(24, dtype=np.float64)
    d2 = (u[None, :, None] - cells[:, 0, None, None]) ** 2 + (u[None, None, :] - cells[:, 1, None, None]) ** 2
    want = np.exp(-d2 / (2 * 1.5**2))[mask].max(axis=0)
    got = np.asarray(mm.gaussian_heatmap(jnp.asarray(cells), jnp.asarray(mask), 24, 1.5))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
    assert not np.asarray(mm.gaussian_heatmap(jnp.asarray(cells), jnp.zeros(9, bool), 24, 1.5)).any()


def test_conv1x1_is_a_one_by_one_convolution():
    import flax.linen as nn

    from jaxmotion.nn.linear import Conv1x1

    x = jax.random.normal(jax.random.key(0), (2, 5, 6, 3))
    layer = Conv1x1(4)
    params = layer.init(jax.random.key(1), x)
    conv = nn.Conv(4, (1, 1))
    assert jax.tree.map(jnp.shape, params) == jax.tree.map(jnp.shape, conv.init(jax.random.key(1), x))

    def loss(module):
        return lambda p, x: jnp.sum(jnp.tanh(module.apply(p, x)) * jnp.arange(4.0))

    np.testing.assert_allclose(layer.apply(params, x), conv.apply(params, x), rtol=1e-5, atol=1e-6)
    for a, b in zip(jax.tree.leaves(jax.grad(loss(layer), argnums=(0, 1))(params, x)),
                    jax.tree.leaves(jax.grad(loss(conv), argnums=(0, 1))(params, x))):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_codebook_is_the_mean_code_of_a_cell_and_fills_empty_cells_from_the_nearest():
    cells = np.array([[1, 1], [1, 1], [6, 6]])
    codes = np.array([[1.0, 0.0], [3.0, 2.0], [-5.0, 5.0]], np.float32)
    table, filled = mm.build_codebook(cells, codes, 8)
    np.testing.assert_allclose(table[1, 1], [2.0, 1.0])
    np.testing.assert_allclose(table[6, 6], [-5.0, 5.0])
    assert filled.sum() == 2
    np.testing.assert_allclose(table[0, 2], [2.0, 1.0])  # nearer (1, 1)
    np.testing.assert_allclose(table[7, 5], [-5.0, 5.0])  # nearer (6, 6)


def test_peaks_of_a_hand_made_map_come_in_confidence_order():
    hm = np.zeros((2, 16, 16), np.float32)
    hm[0, 3, 4], hm[0, 10, 12], hm[0, 12, 2], hm[0, 8, 8] = 0.6, 0.9, 0.75, 0.2  # 0.2 < 0.35 * 0.9
    hm[0, 3, 5] = 0.5  # a shoulder of (3, 4), not a peak
    hm[0, 10, 13] = 0.9  # a plateau with (10, 12): one peak only
    hm[1, 7, 7] = 1.0
    p = mm.find_peaks(jnp.asarray(hm), min_distance=2, threshold_rel=0.35, max_peaks=6)
    cells, conf, valid = np.asarray(p.cells), np.asarray(p.confidence), np.asarray(p.valid)
    assert valid[0].sum() == 3 and valid[1].sum() == 1
    assert tuple(cells[0, 0]) in {(10, 12), (10, 13)}
    assert [tuple(c) for c in cells[0, 1:3]] == [(12, 2), (3, 4)]
    np.testing.assert_allclose(conf[0, :3], [0.9, 0.75, 0.6])
    assert tuple(cells[1, 0]) == (7, 7)
    # Fixed K: the top peaks, then the ranking again.
    assert np.asarray(mm.top_k_slots(p.valid, 5)).tolist() == [[0, 1, 2, 0, 1], [0, 0, 0, 0, 0]]


def test_heteroscedastic_nll_is_minimised_at_sigma_squared_equal_to_the_error():
    err = jnp.array([0.01, 0.5, 4.0])
    grid = jnp.linspace(-4, 2, 6001)
    vals = jax.vmap(lambda ls: mm.heteroscedastic_nll(err, jnp.full(3, ls)))(grid)  # (g, 3)
    best = grid[jnp.argmin(vals, axis=0)]
    np.testing.assert_allclose(np.exp(2 * np.asarray(best)), np.asarray(err), rtol=3e-3)
    g = jax.grad(lambda ls: mm.heteroscedastic_nll(err, ls).sum())(0.5 * jnp.log(err))
    np.testing.assert_allclose(np.asarray(g), 0.0, atol=1e-5)


def test_weighted_bce_matches_its_definition():
    logits, t = jnp.array([-2.0, 0.0, 3.0]), jnp.array([1.0, 0.3, 0.0])
    s = jax.nn.sigmoid(logits)
    want = -(10 * t * jnp.log(s) + (1 - t) * jnp.log(1 - s))
    np.testing.assert_allclose(np.asarray(mm.weighted_bce(logits, t, 10.0)), np.asarray(want), rtol=1e-5)


def test_mm_errors_transferred_equals_plain_errors_on_one_skeleton():
    rng = np.random.default_rng(2)
    y = rng.normal(size=(5, 6, 48)).astype(np.float32)
    pose = np.broadcast_to(y[0, 0], (3, 48)).astype(np.float32)
    futures = np.asarray(mm.motion_transfer(jnp.asarray(y), jnp.asarray(pose[0]), PARENTS))  # all on pose's skeleton
    pred = jnp.asarray(futures[None, :2].repeat(3, 0))
    idx, mask = jnp.array([[0, 1], [2, 3], [4, 0]]), jnp.array([[True, True], [True, False], [True, False]])
    a, f = metrics.mm_errors_transferred(pred, jnp.asarray(pose), jnp.asarray(y), idx, mask, PARENTS)
    # The blocked Gram kernel (metrics._mm_window) rounds a zero distance to about sqrt(eps) * |x|
    # (|x| ~ 10 for these random chained links), so "zero" is zero to 5e-3 here.
    assert float(a[0]) == pytest.approx(0.0, abs=5e-3) and float(f[0]) == pytest.approx(0.0, abs=5e-3)
    d = np.linalg.norm(futures[None, :2] - futures[2][None, None], axis=-1)
    assert float(a[1]) == pytest.approx(d.mean(-1).min(), rel=1e-4)


def test_grid_scaling_puts_every_point_inside_the_grid():
    pts = np.random.default_rng(3).normal(size=(100, 2)).astype(np.float32) * [5, 1]
    origin, scale = mm.grid_scaling(pts, 32)
    cells = np.asarray(mm.to_cells(jnp.asarray(pts), jnp.asarray(origin), scale, 32))
    assert cells.min() >= 1 and cells.max() <= 30  # the 2% margins


def test_tsne_embed_separates_clusters():
    pytest.importorskip("openTSNE")
    rng = np.random.default_rng(4)
    centres = rng.normal(size=(3, 16)) * 5
    codes = np.concatenate([c + 0.1 * rng.normal(size=(60, 16)) for c in centres]).astype(np.float32)
    pts = mm.tsne_embed(codes, fit_points=90, perplexity_fit=20.0, perplexity_transform=10.0)
    lab = np.repeat(np.arange(3), 60)
    means = np.stack([pts[lab == k].mean(0) for k in range(3)])
    within = np.mean([np.linalg.norm(pts[lab == k] - means[k], axis=-1).mean() for k in range(3)])
    between = np.min([np.linalg.norm(means[a] - means[b]) for a in range(3) for b in range(a + 1, 3)])
    assert between > 3 * within


def test_tsne_embed_fitted_on_every_code_separates_clusters():
    pytest.importorskip("openTSNE")
    rng = np.random.default_rng(5)
    centres = rng.normal(size=(3, 16)) * 5
    codes = np.concatenate([c + 0.1 * rng.normal(size=(50, 16)) for c in centres]).astype(np.float32)
    pts = mm.tsne_embed(codes, fit_points=None, perplexity_fit=20.0)
    lab = np.repeat(np.arange(3), 50)
    means = np.stack([pts[lab == k].mean(0) for k in range(3)])
    within = np.mean([np.linalg.norm(pts[lab == k] - means[k], axis=-1).mean() for k in range(3)])
    between = np.min([np.linalg.norm(means[a] - means[b]) for a in range(3) for b in range(a + 1, 3)])
    assert pts.shape == (150, 2) and between > 3 * within


def test_member_subsets_keep_one_member_per_cell_before_the_cap():
    from types import SimpleNamespace

    from jaxmotion.methods.motionmap import Pool

    # Window 0's set: 40 members in 3 cells (cells 0, 1 and 2 hold 30, 8 and 2 of them); window 1's: 2 members.
    idx = np.zeros((2, 40), np.int32)
    idx[0] = np.arange(40)
    idx[1, :2] = [3, 35]
    mask = np.zeros((2, 40), bool)
    mask[0], mask[1, :2] = True, True
    cells = np.asarray([[0, 0]] * 30 + [[5, 7]] * 8 + [[9, 1]] * 2, np.int32)
    pool = SimpleNamespace(sets=(idx, mask))
    rng = np.random.default_rng(0)
    members, ok = Pool.member_subsets(pool, rng, np.asarray([0, 1]), 4, cells)
    assert ok.sum(1).tolist() == [3, 2]
    assert sorted(map(tuple, cells[members[0, :3]])) == [(0, 0), (5, 7), (9, 1)]
    # Without cells, a random 4 of the 40: most draws hold only the crowded cells.
    distinct = [len({tuple(cells[m]) for m in Pool.member_subsets(pool, rng, np.asarray([0]), 4)[0][0]}) for _ in range(50)]
    assert np.mean(distinct) < 2.5


def test_all_peaks_is_zero_velocity_then_every_valid_peak():
    rng = np.random.default_rng(1)
    b, p, t, d = 2, 4, 5, 6
    futures = jnp.asarray(rng.normal(size=(b, p, t, d)), jnp.float32)
    valid = jnp.asarray([[True, True, False, False], [True, False, False, False]])
    modes = mm.Modes(futures, jnp.zeros((b, p)), jnp.zeros((b, p, t, 2)), jnp.zeros((b, p, 2), jnp.int32), valid, jnp.zeros((b, 8, 8)))
    x = jnp.asarray(rng.normal(size=(b, 3, d)), jnp.float32)
    out = np.asarray(mm.all_peaks(modes, x))
    assert out.shape == (b, p + 1, t, d)
    zv = np.broadcast_to(np.asarray(x)[:, None, -1:, :], (b, 1, t, d))
    np.testing.assert_array_equal(out[:, :1], zv)
    np.testing.assert_array_equal(out[0, 1:3], np.asarray(futures)[0, :2])
    np.testing.assert_array_equal(out[1, 2:], np.broadcast_to(zv[1], (3, t, d)))
    # ANP + 1: window 0 has 2 peaks, window 1 has 1.
    assert mm.distinct_futures(out).tolist() == [3, 2]
    with pytest.raises(ValueError, match="k_protocol"):
        mm.MotionMapConfig(k_protocol="all")


@pytest.mark.slow
def test_predict_modes_shapes_and_select_k():
    dim, t_his, t_pred, size = 48, 15, 10, 16
    c = mm.MotionMapConfig(nh_rnn=16, nh_fuse=16, nh_uncertainty=16, n_uncertainty_layers=2, hm_size=size)
    ae, hm = mm.ae_model(c, dim, t_his, t_pred), mm.heatmap_model(c)
    x = jnp.asarray(np.random.default_rng(5).normal(size=(2, t_his, dim)).astype(np.float32))
    ae_p = ae.init(jax.random.key(0), x, jnp.zeros((2, t_pred, dim)))
    hm_p = hm.init(jax.random.key(1), x)
    cb = {"table": jnp.ones((size, size, 16)), "template": x[0, -1]}
    modes = mm.predict_modes(ae, ae_p, hm, hm_p, cb, x, PARENTS, min_distance=2, threshold_rel=0.35, max_peaks=7, scale=10.0)
    assert modes.futures.shape == (2, 7, t_pred, dim) and modes.sigma.shape == (2, 7, t_pred, dim // 3)
    assert mm.select_k(modes, 4).shape == (2, 4, t_pred, dim)


def test_motionmap_is_registered_and_its_configs_load():
    from pathlib import Path

    from jaxmotion.config import load_config
    from jaxmotion.methods import get_method

    m = get_method("motionmap")
    assert m.reference_futures == "train" and m.config_type is mm.MotionMapConfig
    root = Path(__file__).parents[1] / "experiments" / "configs"
    for name in ("motionmap_synthetic.py", "motionmap_bandai.py"):
        cfg = load_config(root / name)
        assert cfg.method == "motionmap" and isinstance(cfg.method_config, mm.MotionMapConfig)


@pytest.mark.slow
def test_every_stage_trains_resumes_and_predicts_on_small_synthetic_data(tmp_path):
    pytest.importorskip("openTSNE")
    from jaxmotion import experiment
    from jaxmotion.config import Config
    from jaxmotion.data.synthetic import make_synthetic
    from jaxmotion.methods import motionmap as mmm
    from jaxmotion.train import runner

    ds = make_synthetic(0, num_train_subjects=2, train_sequences=2, train_segments=6, test_sequences=1, test_segments=3)
    prep = experiment.prepare(ds)
    c = mm.MotionMapConfig(nh_rnn=32, nh_fuse=32, nh_uncertainty=32, n_uncertainty_layers=2, hm_size=16,
                           ae_steps=6, hm_steps=6, ft_steps=6, batch_size=8, tsne_fit_points=None, dedupe_members=True,
                           k_protocol="release")
    cfg = Config(name="t", method="motionmap", action_metrics=False, method_config=c, eval_k=(6,), ckpt_every=3, log_every=3)
    method = experiment.get_method("motionmap")
    trained = runner.train(method, cfg, prep, tmp_path)
    assert set(trained) == {"autoencoder", "codebook", "heatmap", "finetune"}
    restored = runner.restore(method, cfg, prep, tmp_path)
    np.testing.assert_array_equal(np.asarray(restored["codebook"]["table"]), np.asarray(trained["codebook"]["table"]))
    # The cells' action labels survive the checkpoint (synthetic: the modes the training futures follow).
    assert mmm.labels(restored) == mmm.labels(trained) and set(mmm.labels(trained)) <= set(ds.info["mode_names"])
    np.testing.assert_array_equal(np.asarray(restored["codebook"]["label_counts"]), np.asarray(trained["codebook"]["label_counts"]))
    # The encoders are not fine-tuned.
    enc = lambda p: np.asarray(p["params"]["enc_x"]["cell"]["weight_hh"])
    np.testing.assert_array_equal(enc(trained["finetune"]), enc(trained["autoencoder"]))
    fns = method.predictors(cfg, ds, trained, 6)
    out = np.asarray(fns["motionmap"](jnp.asarray(prep.x[:4]), jax.random.key(0)))
    assert out.shape == (4, 6, ds.t_pred, ds.dim) and np.all(np.isfinite(out))
    every = np.asarray(fns["motionmap_all_peaks"](jnp.asarray(prep.x[:4]), jax.random.key(0)))
    assert every.shape == (4, c.max_peaks + 1, ds.t_pred, ds.dim)
    np.testing.assert_array_equal(every[:, 0], np.repeat(prep.x[:4, -1:], ds.t_pred, axis=1))
    st = mmm.known_mode_statistics(cfg, prep, trained)
    assert st["true_modes_per_window"] == 6 and st["predicted_modes_mean"] >= 1
    assert len(mmm.draw_pictures(cfg, prep, trained, tmp_path)) == 2
