"""Properties of the synthetic multimodal dataset and its known test modes."""

import numpy as np
import pytest

from jaxmotion.data import synthetic as syn
from jaxmotion.data import windows  # not `from ... import test_windows`: pytest would collect it


@pytest.fixture(scope="module")
def ds():
    return syn.make_synthetic(0)


@pytest.fixture(scope="module")
def modes(ds):
    return syn.test_modes(ds)


@pytest.fixture(scope="module")
def test_wins(ds):
    return windows.test_windows(windows.sequence_frames(ds.test), ds.t_his, ds.t_pred)


def _ade_terms(m):
    """Pairwise ADE-terms `(N, 6, 6)` between the modes of each window."""
    return np.linalg.norm(m[:, :, None] - m[:, None, :], axis=-1).mean(-1)


def test_dataset_fields_and_sizes(ds, test_wins):
    assert (ds.name, ds.fps, ds.t_his, ds.t_pred, ds.dim) == ("synthetic", 30.0, 15, 60, 48)
    assert ds.mm_threshold == syn.MM_THRESHOLD
    assert len(ds.train) == 5 * 8 and len(ds.test) == 2 * 4
    assert {s.subject for s in ds.train}.isdisjoint({s.subject for s in ds.test})
    assert all(s.positions.shape == (20 * 60, 17, 3) for s in ds.train)
    # DLow start rule: range(0, 600 - 75, 15) has 35 starts per test sequence.
    assert test_wins[0].shape == (8 * 35, 75, 48)
    for s in ds.train + ds.test:
        assert np.all(np.isfinite(s.positions)) and s.action == "mixed"


def test_deterministic_given_seed(ds):
    again, other = syn.make_synthetic(0), syn.make_synthetic(1)
    assert len(ds.train + ds.test) == len(again.train + again.test) > 0
    for a, b in zip(ds.train + ds.test, again.train + again.test):
        np.testing.assert_array_equal(a.positions, b.positions)
    assert len(ds.info["train_segments"]) == len(again.info["train_segments"]) == len(other.info["train_segments"]) > 0
    for a, b in zip(ds.info["train_segments"], again.info["train_segments"]):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(ds.test[0].positions, other.test[0].positions)
    pairs = zip(ds.info["train_segments"], other.info["train_segments"])
    assert not all(np.array_equal(a, b) for a, b in pairs)


def test_mode_table_is_multimodal_and_imbalanced():
    probs = np.asarray(syn.MODE_PROBS)
    assert len(syn.MODE_NAMES) == len(probs) >= 5
    assert probs.sum() == pytest.approx(1.0) and probs.min() <= 0.05


def test_sampler_matches_probs():
    draws = syn.sample_actions(np.random.default_rng(0), 200_000)
    freq = np.bincount(draws, minlength=6) / draws.size
    np.testing.assert_allclose(freq, syn.MODE_PROBS, atol=0.005)


def test_train_segment_frequencies_match_probs(ds):
    segs = np.concatenate(ds.info["train_segments"])
    freq = np.bincount(segs, minlength=6) / segs.size
    p = np.asarray(syn.MODE_PROBS)
    assert np.all(np.abs(freq - p) < 4 * np.sqrt(p * (1 - p) / segs.size))
    assert np.array_equal(syn.frame_labels(ds.info["train_segments"][0])[::60], ds.info["train_segments"][0])


def test_true_future_is_exactly_the_chosen_mode(ds, modes, test_wins):
    future = test_wins[0][:, ds.t_his :]
    assert modes.modes.shape == (len(future), 6, 60, 48) and modes.modes.dtype == np.float32 and len(future) > 0
    equal = np.array([[np.array_equal(m, y) for m in ms] for ms, y in zip(modes.modes, future)])
    assert np.all(equal.sum(1) == 1)
    np.testing.assert_array_equal(equal.argmax(1), modes.true_mode)
    np.testing.assert_allclose(modes.probs, syn.MODE_PROBS)


def test_mm_futures_are_modes_of_the_window(ds, modes, test_wins):
    # At the documented threshold, multimodal ground truth (protocol §2 (docs/pages/protocol.md#metrics)) is exact: every
    # MM neighbour's future is one of the window's own known modes.
    w = test_wins[0]
    last, future = w[:, ds.t_his - 1], w[:, ds.t_his :]
    mm = np.linalg.norm(last[:, None] - last[None], axis=-1) < ds.mm_threshold
    assert 10 < mm.sum(1).mean() < 20
    for i, j in zip(*np.nonzero(mm)):
        assert np.any(np.all(modes.modes[i] == future[j], axis=(-1, -2)))


def test_modes_share_the_deterministic_part_then_split(modes):
    m, b = modes.modes, modes.boundary
    assert set(b.tolist()) == {0, 15, 30, 45}
    d = _ade_terms(m)
    off_diag = ~np.eye(6, dtype=bool)
    for i in range(len(m)):
        # Frame b is the neutral pose for every action; the actions differ only afterwards.
        assert np.all(m[i, :, : b[i] + 1] == m[i, :1, : b[i] + 1])
        after = m[i, :, b[i] + 1 :]
        assert np.all(np.abs(after[:, None] - after[None]).max((-1, -2))[off_diag] > 0)
    aligned = b == 0
    assert d[aligned][:, off_diag].min() > 0.3  # metres: far apart compared with a few cm per joint
    assert d[~aligned][:, off_diag].min() > 0.03


def test_segments_chain_continuously_on_the_ground(ds):
    for s in ds.train[:5] + ds.test:
        step = np.linalg.norm(np.diff(s.positions, axis=0), axis=-1)
        assert step.max() < 0.2  # metres per frame: no jumps at segment boundaries
        boundaries = s.positions[::60]
        np.testing.assert_allclose(boundaries, boundaries[:1].repeat(len(boundaries), 0), atol=1e-6)
        lowest_ankle = s.positions[:, [syn.RFOOT, syn.LFOOT], 1].min(1)
        np.testing.assert_allclose(lowest_ankle, 0.0, atol=0.005)


def test_bone_lengths_constant_in_time_and_vary_by_subject(ds):
    parents = np.asarray(syn.PARENTS)

    def bones(s):
        return np.linalg.norm(s.positions[:, 1:] - s.positions[:, parents[1:]], axis=-1)

    per_subject = {}
    for s in ds.train + ds.test:
        b = bones(s)
        assert np.abs(b - b[0]).max() < 1e-5
        per_subject.setdefault(s.subject, b[0])
    lengths = np.stack(list(per_subject.values()))
    assert len(lengths) == 7
    gaps = np.abs(lengths[:, None] - lengths[None]).max(-1)
    assert gaps[~np.eye(7, dtype=bool)].min() > 0.005


def test_left_right_pairs_mirror_names():
    for left, right in syn.LEFT_RIGHT_PAIRS:
        ln, rn = syn.JOINT_NAMES[left], syn.JOINT_NAMES[right]
        assert ln[0] == "L" and rn[0] == "R" and ln[1:] == rn[1:]
        # Mirroring must map the skeleton onto itself: parents are the same joint or a pair too.
        pl, pr = syn.PARENTS[left], syn.PARENTS[right]
        assert pl == pr or (pl, pr) in syn.LEFT_RIGHT_PAIRS


def test_test_modes_rejects_foreign_or_edited_data(ds):
    bare = syn.make_synthetic(0)
    bare.info = {}
    with pytest.raises(ValueError, match="info"):
        syn.test_modes(bare)
    edited = syn.make_synthetic(0)
    edited.test = edited.test[1:]
    with pytest.raises(ValueError, match="do not edit"):
        syn.test_modes(edited)


def test_bad_sizes_raise():
    with pytest.raises(ValueError, match="test_segments"):
        syn.make_synthetic(0, test_segments=1)
    with pytest.raises(ValueError, match="train_sequences"):
        syn.make_synthetic(0, train_sequences=0)
