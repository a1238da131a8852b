"""Training-window samplers: every window equally likely, a sequence then a start, or the releases' subject-first draw."""

import numpy as np
import pytest

from jaxmotion.data.windows import TrainSampler

T_TOTAL = 10


def _frames():
    # A short sequence (frames valued 0) and a long one (valued 1); window content tells the source.
    return [np.zeros((20, 3), np.float32), np.ones((200, 3), np.float32), np.full((T_TOTAL, 3), 2.0, np.float32)]


def test_window_weighting_draws_sequences_in_proportion_to_their_windows():
    s = TrainSampler(_frames(), T_TOTAL)
    batch = s.sample(np.random.default_rng(0), 4000)
    src = batch[:, 0, 0]
    counts = {v: np.mean(src == v) for v in (0.0, 1.0, 2.0)}
    n = np.array([11, 191, 1])  # valid starts per sequence
    for v, share in zip((0.0, 1.0, 2.0), n / n.sum()):
        assert counts[v] == pytest.approx(share, abs=0.02)
    assert s.num_windows == 203


def test_sequence_weighting_is_dlows_release():
    s = TrainSampler(_frames(), T_TOTAL, weighting="sequences")
    batch = s.sample(np.random.default_rng(0), 4000)
    src = batch[:, 0, 0]
    # The sequence of exactly t_total frames is never drawn; the other two are equally likely.
    assert not np.any(src == 2.0)
    assert np.mean(src == 0.0) == pytest.approx(0.5, abs=0.03)
    assert len(s.frames) == 2


def test_subject_weighting_is_the_releases_sample():
    # Subject A: the short sequence, the long one and one of exactly t_total frames; subject B: one
    # sequence. A subject is drawn uniformly, then one of its sequences (>= t_total frames), redrawn
    # when it has exactly t_total: B's gets 1/2 / (1 - 1/6) = 0.6, A's two others 0.2 each.
    frames = _frames() + [np.full((50, 3), 3.0, np.float32)]
    s = TrainSampler(frames, T_TOTAL, weighting="subjects", subjects=["A", "A", "A", "B"])
    src = s.sample(np.random.default_rng(0), 6000)[:, 0, 0]
    assert not np.any(src == 2.0)
    for v, share in ((0.0, 0.2), (1.0, 0.2), (3.0, 0.6)):
        assert np.mean(src == v) == pytest.approx(share, abs=0.02)
    with pytest.raises(ValueError, match="subject name per sequence"):
        TrainSampler(frames, T_TOTAL, weighting="subjects")


def test_bad_weighting_is_named():
    with pytest.raises(ValueError, match="weighting"):
        TrainSampler(_frames(), T_TOTAL, weighting="takes")
