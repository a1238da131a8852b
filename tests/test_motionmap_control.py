"""MotionMap's controllability (labels per cell, modes by label, futures near a mode) and `Method.pictures` in the report."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.methods import motionmap as mmm
from jaxmotion.models import motionmap as mm


def test_label_counts_per_cell_and_an_empty_cell_takes_its_nearest_filled_cells():
    cells = np.array([[1, 1], [1, 1], [1, 1], [6, 6]])
    counts = mm.cell_label_counts(cells, np.array([0, 1, 1, 2]), 3, 8)
    assert counts.shape == (8, 8, 3)
    assert counts[1, 1].tolist() == [1, 2, 0] and counts[6, 6].tolist() == [0, 0, 1]
    assert counts[0, 2].tolist() == [1, 2, 0]  # empty, nearer (1, 1)
    assert counts[7, 5].tolist() == [0, 0, 1]  # empty, nearer (6, 6)
    # The labels come from the same cell whose code the table holds.
    table, _ = mm.build_codebook(cells, np.array([[1.0], [1.0], [1.0], [-1.0]], np.float32), 8)
    assert np.all((counts.argmax(-1) == 2) == (table[..., 0] < 0))
    with pytest.raises(ValueError, match="one label in"):
        mm.cell_label_counts(cells, np.array([0, 1, 3, 2]), 3, 8)


def _hand_made_modes():
    """Two windows, four peaks each, ranked by confidence; the futures hold their peak's id; label grid 8 x 8 x 3."""
    counts = np.zeros((8, 8, 3), np.int32)
    counts[..., 0] = 1  # label 0 everywhere, except:
    counts[2, 2, 1] = counts[5, 5, 1] = counts[6, 1, 1] = 3
    counts[4, 4] = [2, 2, 0]  # a tie: the lower label
    cells = np.array([[[0, 0], [2, 2], [4, 4], [5, 5]], [[0, 0], [4, 4], [6, 1], [7, 7]]], np.int32)
    conf = np.array([[0.9, 0.8, 0.7, 0.6], [0.9, 0.8, 0.7, 0.0]], np.float32)
    valid = np.array([[True] * 4, [True, True, False, False]])  # window 1's label-1 cell (6, 1) is padding
    futures = np.arange(8, dtype=np.float32).reshape(2, 4, 1, 1)
    modes = mm.Modes(jnp.asarray(futures), jnp.asarray(conf), jnp.asarray(futures), jnp.asarray(cells),
                     jnp.asarray(valid), jnp.zeros((2, 8, 8)))
    return modes, jnp.asarray(counts)


def test_select_label_keeps_the_modes_of_that_label_in_confidence_order():
    modes, counts = _hand_made_modes()
    out = jax.jit(mm.select_label)(modes, counts, jnp.int32(1))  # the label may be traced
    np.testing.assert_array_equal(np.asarray(out.valid), [[True, True, False, False], [False] * 4])
    np.testing.assert_array_equal(np.asarray(out.futures)[0, :2, 0, 0], [1.0, 3.0])  # peaks (2, 2), (5, 5)
    np.testing.assert_array_equal(np.asarray(out.cells)[0, :2], [[2, 2], [5, 5]])
    np.testing.assert_allclose(np.asarray(out.confidence), [[0.8, 0.6, 0, 0], [0, 0, 0, 0]])
    np.testing.assert_array_equal(np.asarray(out.sigma), np.asarray(out.futures))  # every field moves together
    # Label 0: the tie at (4, 4) goes to it.
    out0 = mm.select_label(modes, counts, 0)
    np.testing.assert_array_equal(np.asarray(out0.cells)[:, :2], [[[0, 0], [4, 4]], [[0, 0], [4, 4]]])
    assert np.asarray(out0.valid).sum(1).tolist() == [2, 2]


@pytest.mark.parametrize("radius", [0.0, 1.0, 3.5])
def test_disc_cells_stay_within_the_radius_and_inside_the_grid(radius):
    centre = jnp.array([[10, 10], [0, 1], [15, 15]], jnp.int32)
    cells = np.asarray(mm.disc_cells(jax.random.key(0), centre, k=400, radius=radius, size=16))
    assert cells.shape == (3, 400, 2) and cells.min() >= 0 and cells.max() <= 15
    assert np.linalg.norm(cells - np.asarray(centre)[:, None], axis=-1).max() <= radius
    # In the middle of the grid every cell of the disc is drawn.
    r = np.arange(-4, 5)
    n_disc = int((r[:, None] ** 2 + r[None] ** 2 <= radius**2).sum())
    assert len({tuple(c) for c in cells[0]}) == n_disc


class _StubAE(mm.MotionMapAE):
    """Decodes a code as `x[-1] + code` at every future frame, log sigma 0: which code went with which window shows."""

    def apply(self, params, x, z, method=None):
        t_his, dim = x.shape[1], x.shape[2]
        fut = jnp.repeat((x[:, -1] + z[:, :dim])[:, None], 3, axis=1)
        return jnp.concatenate([x, fut], axis=1), jnp.zeros((x.shape[0], t_his + 3, dim // 3))


def test_sample_near_mode_decodes_the_codes_of_cells_within_the_radius():
    size, dim = 8, 6
    x = jnp.asarray(np.random.default_rng(0).normal(size=(2, 4, dim)).astype(np.float32))
    table = jnp.asarray(np.random.default_rng(1).normal(size=(size, size, dim)).astype(np.float32))
    centre = jnp.array([[3, 3], [7, 0]], jnp.int32)
    near = jax.jit(lambda x, c, key: mm.sample_near_mode(_StubAE(dim, 4, 3), None, table, x, c, key, k=5, radius=2.0, scale=10.0))
    out = near(x, centre, jax.random.key(2))
    assert out.futures.shape == (2, 5, 3, dim) and out.sigma.shape == (2, 5, 3, dim // 3)
    cells = np.asarray(out.cells)
    assert np.linalg.norm(cells - np.asarray(centre)[:, None], axis=-1).max() <= 2.0
    want = np.asarray(x)[:, None, -1] + np.asarray(table)[cells[..., 0], cells[..., 1]]  # (2, 5, dim)
    np.testing.assert_allclose(np.asarray(out.futures), np.repeat(want[:, :, None], 3, 2), atol=1e-6)
    np.testing.assert_allclose(np.asarray(out.sigma), 0.1)  # exp(0) / scale


def test_labels_of_a_codebook_round_trip_and_an_old_codebook_says_what_to_retrain():
    fields = mmm._label_fields(np.array([[0, 0], [1, 1], [1, 1]]), np.array(["walk", "wave-left-hand", "walk"]), 4)
    assert mmm.labels({"codebook": fields}) == ["walk", "wave-left-hand"]
    assert np.asarray(fields["label_counts"])[1, 1].tolist() == [1, 1]
    with pytest.raises(ValueError, match="no action labels per cell.*codebook/, heatmap/ and finetune/"):
        mmm.label_modes_fn(None, None, {"codebook": {"table": jnp.zeros((4, 4, 2))}}, "walk")
    with pytest.raises(ValueError, match=r"'run' is not a label.*\['walk', 'wave-left-hand'\]"):
        mmm.label_modes_fn(None, None, {"codebook": fields}, "run")


def test_future_labels_are_the_sequence_action_or_the_synthetic_mode_the_future_follows():
    from jaxmotion.data.synthetic import MODE_NAMES, make_synthetic

    ds = make_synthetic(0, num_train_subjects=1, train_sequences=2, train_segments=4, test_sequences=1, test_segments=3)
    seq, starts = np.array([0, 0, 1]), np.array([0, 50, 105])  # the futures' last frames 74, 124, 179: segments 1, 2, 2
    got = mmm.future_labels(ds, seq, starts)
    segs = ds.info["train_segments"]
    assert got.tolist() == [MODE_NAMES[segs[0][1]], MODE_NAMES[segs[0][2]], MODE_NAMES[segs[1][2]]]
    plain = dataclasses.replace(ds, info={})
    assert mmm.future_labels(plain, seq, starts).tolist() == ["mixed"] * 3


def test_report_draws_the_methods_pictures_of_the_window_it_draws(tmp_path, monkeypatch):
    from jaxmotion import experiment, method
    from jaxmotion.config import Config
    from jaxmotion.data.synthetic import make_synthetic

    ds = make_synthetic(0, num_train_subjects=1, train_sequences=1, train_segments=3, test_sequences=1, test_segments=3)
    prep = experiment.prepare(ds)
    calls = []

    def pictures(cfg, prep_, params, workdir, i):
        calls.append((prep_ is prep, params, i))
        path = workdir / "toy.png"
        path.write_bytes(b"")
        return [path]

    def predictors(cfg, ds_, params, k):  # zero velocity
        return {"toy": jax.jit(lambda x, key: jnp.repeat(x[:, None, -1:], k, 1).repeat(ds.t_pred, 2))}

    toy = method.Method(name="toy_pictures", config_type=dict, stages=lambda cfg, prep_: [], predictors=predictors,
                        pictures=pictures)
    monkeypatch.setitem(method._REGISTRY, "toy_pictures", toy)
    # The still and the GIF are other tests' business (and slow): stand-ins that write the still's file.
    monkeypatch.setattr("jaxmotion.pictures.viz.plot_futures", lambda x, p, y, parents, path, title: (path.write_bytes(b""), path)[1])
    monkeypatch.setattr("jaxmotion.pictures.animate.animate_futures", lambda *a, **k: None)
    cfg = Config(name="t", method="toy_pictures", eval_k=(2,))
    png = experiment.report(cfg, prep, {"p": 1}, tmp_path)
    assert png == tmp_path / "samples.png" and png.exists()
    assert calls == [(True, {"p": 1}, int(experiment.most_multimodal(prep, 1)[0]))]
