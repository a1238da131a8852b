"""Metrics that need action labels: BeLFusion's CMD and an FID over a project-trained action classifier ([protocol §3][realism-and-action-metrics]).

CMD (cumulative motion distribution, BeLFusion Sec. 4 / `metrics/evaluation.py` `cmd`). For class c,
`M_t` is the mean over the class's test windows, their K samples and the points of a frame of the
displacement `||p_t - p_{t-1}||` of the predicted future (`displacement_profile`), t = 1..T-1 with
T = t_pred; `Mbar_c` is the same mean displacement of the class's ground-truth training futures,
one number (over windows, frames and points; `reference_displacement`). Then

    CMD_c = sum_{t=1}^{T-1} (T - t) |M_t - Mbar_c|,        CMD = sum_c (n_c / n) CMD_c

with `n_c` the class's test windows. Early frames weigh most. CMD is 0 when the predictions move
exactly as much as the class's training futures do on average, at every frame.

FID: the Frechet distance `||mu_a - mu_b||^2 + Tr(S_a + S_b - 2 (S_a S_b)^{1/2})` between Gaussians
fitted to the features of the ground-truth test futures and of all K predicted futures of every
test window (`frechet_distance`, by eigen-decompositions of symmetric matrices). The features are
the penultimate layer of `jaxmotion.models.action_classifier.ActionClassifier`, trained once per
dataset by `dataset_classifier` and cached on disk. It is NOT BeLFusion's Human3.6M classifier:
FID values compare only within this project, on the same dataset.

Labels (`window_labels`): a Bandai-Namco-2 window (joints or markers) takes its sequence's content
label (`Sequence.action`: `walk`, `wave-left-hand`, ...); a synthetic window takes the action of
the segment that holds most of its future frames (the later one on a tie); a dataset with
`info["action_labels"] = True` takes its sequences' `action`. Other datasets have no labels here:
a plain BVH folder's `action` is its file name, and Human3.6M / HumanEva-I are not wired up.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization
from jaxtyping import Array, ArrayLike, Float, Int

from jaxmotion.data.datasets import default_cache_dir
from jaxmotion.formats.atomic import write_bytes_atomic
from jaxmotion.data.types import MotionDataset
from jaxmotion.data.windows import canonicalise_windows, split_frames, test_windows
from jaxmotion.models import action_classifier as ac
from jaxmotion.models.action_classifier import ClassifierConfig
from jaxmotion.train.action_classifier import train as train_classifier

CACHE_VERSION = 1  # bump when training or the file layout changes: old cache entries are then ignored

# --------------------------------------------------------------------------------------------
# Labels.


def has_action_labels(ds: MotionDataset) -> bool:
    """Returns whether `window_labels` gives labels for `ds` (module docstring, Labels)."""
    flag = ds.info.get("action_labels")
    if flag is not None:
        return bool(flag)
    if {"train_segments", "test_segments", "mode_names", "segment_len"} <= set(ds.info):
        return True
    return ds.name == "bandai2" or ds.name.startswith("bandai2_markers_")


def window_labels(
    ds: MotionDataset, seq_index: Int[np.ndarray, " n"], starts: Int[np.ndarray, " n"], split: str = "test"
) -> np.ndarray | None:
    """Returns the action label (a string) of each window `(getattr(ds, split)[seq_index], starts)`, or None without labels.

    Windows are `t_his + t_pred` frames from `starts` (test windows: `experiment.Prepared.seq_index`
    and `.starts`). Synthetic data (per-segment actions `info[f"{split}_segments"]`): the action of
    the segment holding most of the future's frames, the later one on a tie. MotionMap's
    `future_labels` takes the last future frame's segment instead (the mode a window follows);
    for a classifier of the future's motion the majority of its frames is the better target: a
    future that enters a new segment 15 frames before its end shows little of that action.
    """
    if split not in ("train", "test"):
        raise ValueError(f"window_labels: split must be 'train' or 'test', got {split!r}")
    if not has_action_labels(ds):
        return None
    seq_index, starts = np.asarray(seq_index, np.int64), np.asarray(starts, np.int64)
    if seq_index.shape != starts.shape:
        raise ValueError(f"window_labels: seq_index {seq_index.shape} and starts {starts.shape} differ in shape")
    seqs = getattr(ds, split)
    if len(seq_index) and (seq_index.min() < 0 or seq_index.max() >= len(seqs)):
        raise ValueError(f"window_labels: seq_index outside the {len(seqs)} {split} sequences")
    info = ds.info
    if f"{split}_segments" in info and "segment_len" in info:
        length, names = info["segment_len"], info["mode_names"]
        first, last = starts + ds.t_his, starts + ds.t_total - 1
        span = (ds.t_pred + length - 1) // length + 1  # most segments a future can touch
        best, best_n = first // length, np.zeros_like(first)
        for o in range(span):
            seg = first // length + o
            n = np.clip(np.minimum(last, (seg + 1) * length - 1) - np.maximum(first, seg * length) + 1, 0, None)
            take = n >= best_n  # >=: the later segment wins a tie
            best, best_n = np.where(take & (n > 0), seg, best), np.where(take & (n > 0), n, best_n)
        segments = info[f"{split}_segments"]
        return np.asarray([names[segments[q][s]] for q, s in zip(seq_index, best)])
    return np.asarray([seqs[q].action for q in seq_index])


def _all_windows(ds: MotionDataset, split: str) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Returns `(frames, seq_index, starts)` of every window (every start frame) of a split, uncanonicalised."""
    frames, _ = split_frames(ds, split)
    counts = np.array([max(len(f) - ds.t_total + 1, 0) for f in frames])
    seq_index = np.repeat(np.arange(len(frames)), counts)
    starts = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return frames, seq_index, starts


# --------------------------------------------------------------------------------------------
# CMD.


def displacement_profile(motion: Float[ArrayLike, "... t d"]) -> Float[np.ndarray, "... t-1"]:
    """Returns the mean over a frame's points (`d / 3` of them) of `||p_t - p_{t-1}||`, t = 1..T-1."""
    m = np.asarray(motion, np.float32)
    if m.shape[-1] % 3 or m.shape[-2] < 2:
        raise ValueError(f"displacement_profile: expected (..., T >= 2, 3 * points) frames, got shape {m.shape}")
    p = m.reshape(m.shape[:-1] + (m.shape[-1] // 3, 3))
    return np.linalg.norm(np.diff(p, axis=-3), axis=-1).mean(axis=-1)


@jax.jit
def _mean_profile(pred: Float[Array, "b k t d"]) -> Float[Array, "b t-1"]:
    """Returns `displacement_profile(pred).mean(axis=1)`, fused by XLA (evaluation's chunks of K futures)."""
    # x, y and z as three strided slices rather than a norm over a minor axis of 3, which XLA:CPU
    # reduces slowly: 41 against 87 ms per chunk of 64 x 50 futures of 60 frames on the 2-core Xeon.
    d = jnp.diff(pred, axis=-2)
    return jnp.mean(jnp.sqrt(d[..., 0::3] ** 2 + d[..., 1::3] ** 2 + d[..., 2::3] ** 2), axis=(1, -1))


def class_cmd(profile: Float[ArrayLike, " t1"], reference: float) -> float:
    """Returns `CMD_c = sum_{t=1}^{T-1} (T - t) |M_t - Mbar_c|` of a class's mean profile `M` (T-1 values)."""
    m = np.asarray(profile, np.float64)
    big_t = m.shape[0] + 1
    return float(np.sum((big_t - np.arange(1, big_t)) * np.abs(m - reference)))


def cmd(profiles: Float[ArrayLike, "n t1"], labels: ArrayLike, reference: Mapping[str, float]) -> float:
    """Returns CMD: the class-frequency-weighted sum of `class_cmd` (module docstring).

    `profiles[i]` is window i's displacement profile averaged over its K samples, `labels[i]` its
    class (`(n,)`), `reference[c]` the class's `Mbar_c` (`reference_displacement`).
    """
    profiles, labels = np.asarray(profiles, np.float64), np.asarray(labels)
    if profiles.ndim != 2 or labels.shape != profiles.shape[:1]:
        raise ValueError(f"cmd: expected profiles (n, T-1) and labels (n,), got {profiles.shape} and {labels.shape}")
    classes, counts = np.unique(labels, return_counts=True)
    missing = [str(c) for c in classes if str(c) not in reference]
    if missing:
        raise ValueError(f"cmd: no reference displacement for classes {missing} (have {sorted(reference)})")
    n = labels.shape[0]
    return float(sum(k / n * class_cmd(profiles[labels == c].mean(0), reference[str(c)]) for c, k in zip(classes, counts)))


def reference_displacement(ds: MotionDataset) -> dict[str, float]:
    """Returns `{class: Mbar_c}`: the mean future displacement per frame and point over every training window of the class.

    Every start frame of every training sequence is a window (as the training sampler draws them).
    Displacements are unchanged by a rigid motion, so marker windows need no canonicalisation here.
    """
    frames, seq_index, starts = _all_windows(ds, "train")
    labels = window_labels(ds, seq_index, starts, "train")
    if labels is None:
        raise ValueError(f"reference_displacement: dataset {ds.name!r} has no action labels")
    means = []
    for q, f in enumerate(frames):
        s = starts[seq_index == q]
        if not len(s):
            continue
        c = np.concatenate([[0.0], np.cumsum(displacement_profile(f), dtype=np.float64)])
        # A window's future displacements are those between frames s + t_his .. s + t_total - 1.
        means.append((c[s + ds.t_total - 1] - c[s + ds.t_his]) / (ds.t_pred - 1))
    means = np.concatenate(means)
    return {str(c): float(means[labels == c].mean()) for c in np.unique(labels)}


# --------------------------------------------------------------------------------------------
# Frechet distance.


class Moments(NamedTuple):
    """Running sums of feature vectors: count, sum `(f,)` and sum of outer products `(f, f)`, float64."""

    n: int
    total: Float[np.ndarray, " f"]
    outer: Float[np.ndarray, "f f"]


def moments(features: Float[ArrayLike, "n f"]) -> Moments:
    """Returns the `Moments` of a set of feature vectors (rows)."""
    x = np.asarray(features, np.float64)
    if x.ndim != 2:
        raise ValueError(f"moments: features must be (n, f), got shape {x.shape}")
    return Moments(x.shape[0], x.sum(0), x.T @ x)


def add_moments(a: Moments, b: Moments) -> Moments:
    """Returns the `Moments` of the union of two feature sets."""
    if a.total.shape != b.total.shape:
        raise ValueError(f"add_moments: feature dimensions differ: {a.total.shape[0]} and {b.total.shape[0]}")
    return Moments(a.n + b.n, a.total + b.total, a.outer + b.outer)


def mean_cov(m: Moments) -> tuple[Float[np.ndarray, " f"], Float[np.ndarray, "f f"]]:
    """Returns the mean and the unbiased covariance (`np.cov`'s) of the features summed in `m`."""
    if m.n < 2:
        raise ValueError(f"mean_cov: a covariance needs at least 2 feature vectors, got {m.n}")
    mu = m.total / m.n
    cov = (m.outer - m.n * np.outer(mu, mu)) / (m.n - 1)
    return mu, (cov + cov.T) / 2


def _psd_sqrt(a: np.ndarray, what: str) -> np.ndarray:
    """Returns the symmetric square root of a symmetric positive semi-definite matrix (eigen-decomposition)."""
    w, v = np.linalg.eigh((a + a.T) / 2)
    tol = 1e-9 * max(1.0, float(np.abs(w).max(initial=0.0)))
    if w.min(initial=0.0) < -tol:
        raise ValueError(f"frechet_distance: {what} is not positive semi-definite (eigenvalue {w.min():.3g})")
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


def frechet_distance(
    mu1: Float[ArrayLike, " f1"], cov1: Float[ArrayLike, "f1 f1"], mu2: Float[ArrayLike, " f2"], cov2: Float[ArrayLike, "f2 f2"]
) -> float:
    """Returns `||mu1 - mu2||^2 + Tr(cov1 + cov2 - 2 (cov1 cov2)^{1/2})`, the Frechet distance of two Gaussians.

    `Tr (cov1 cov2)^{1/2}` is computed as `Tr (s cov2 s)^{1/2}` with `s = cov1^{1/2}`: the same
    eigenvalues, but of a symmetric PSD matrix, so no complex parts and no near-singular `sqrtm`.
    """
    mu1, mu2 = np.asarray(mu1, np.float64), np.asarray(mu2, np.float64)
    cov1, cov2 = np.asarray(cov1, np.float64), np.asarray(cov2, np.float64)
    f = mu1.shape[0]
    if mu1.ndim != 1 or mu2.shape != (f,) or cov1.shape != (f, f) or cov2.shape != (f, f):
        raise ValueError(
            f"frechet_distance: feature dimensions differ: mu1 {mu1.shape}, cov1 {cov1.shape}, mu2 {mu2.shape}, cov2 {cov2.shape}"
        )
    for name, x in (("mu1", mu1), ("cov1", cov1), ("mu2", mu2), ("cov2", cov2)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"frechet_distance: {name} contains NaN or inf")
    s = _psd_sqrt(cov1, "cov1")
    _psd_sqrt(cov2, "cov2")  # the check only
    ev = np.linalg.eigvalsh((s @ cov2 @ s + (s @ cov2 @ s).T) / 2)
    tr_sqrt = float(np.sum(np.sqrt(np.clip(ev, 0.0, None))))
    d = mu1 - mu2
    return max(float(d @ d + np.trace(cov1) + np.trace(cov2) - 2.0 * tr_sqrt), 0.0)


def fid(features_a: Float[ArrayLike, "n f1"], features_b: Float[ArrayLike, "m f2"]) -> float:
    """Returns the Frechet distance between Gaussians fitted to two feature sets (rows are samples)."""
    a, b = np.asarray(features_a), np.asarray(features_b)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(f"fid: feature sets must be (n, f) and (m, f) with the same f, got {a.shape} and {b.shape}")
    return frechet_distance(*mean_cov(moments(a)), *mean_cov(moments(b)))


# --------------------------------------------------------------------------------------------
# The dataset's classifier, trained once and cached.


@dataclasses.dataclass
class TrainedClassifier:
    """A trained `ActionClassifier`: its parameters, class names (index order) and `info` (accuracy, budget, ...)."""

    model: ac.ActionClassifier
    params: dict
    classes: tuple[str, ...]
    info: dict

    def features(self, y: Float[ArrayLike, "n t d"], batch: int = 256) -> Float[np.ndarray, "n f"]:
        """Returns the FID features of futures `y`."""
        return ac.predict(self.model, self.params, y, batch)[1]


def classifier_cache_dir() -> Path:
    """Returns the default folder of cached classifiers: `action_classifiers/` beside the Bandai extraction cache."""
    return default_cache_dir().parent / "action_classifiers"


def _test_futures(ds: MotionDataset) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Returns `(futures (N, t_pred, D), seq_index, starts)` of every protocol test window (canonicalised for markers)."""
    frames, canon = split_frames(ds, "test")
    windows, seq_index, starts = test_windows(frames, ds.t_his, ds.t_pred)
    if canon is not None:
        windows = canonicalise_windows(windows, np.stack([canon[i][s] for i, s in zip(seq_index, starts)]))
    return windows[:, ds.t_his :], seq_index, starts


def _cache_key(ds: MotionDataset, c: ClassifierConfig, train_frames, train_labels, test_y, test_labels) -> str:
    h = hashlib.sha1(repr((CACHE_VERSION, ds.name, ds.t_his, ds.t_pred, ds.info.get("frames"), dataclasses.asdict(c))).encode())
    for f in train_frames:
        h.update(np.ascontiguousarray(f).tobytes())
    h.update("\n".join(map(str, train_labels)).encode())
    h.update(np.ascontiguousarray(test_y).tobytes())
    h.update("\n".join(map(str, test_labels)).encode())
    return h.hexdigest()[:20]


def dataset_classifier(
    ds: MotionDataset,
    config: ClassifierConfig = ClassifierConfig(),
    *,
    cache_dir: str | os.PathLike | None = None,
    log: Callable[[str], None] | None = print,
) -> TrainedClassifier | None:
    """Returns `ds`'s action classifier, trained on its training windows, or None when `ds` has no labels.

    Trained once per (data, labels, `config`) and cached in `cache_dir` (default
    `classifier_cache_dir()`) as `<dataset>_<key>.msgpack` (parameters) with `<dataset>_<key>.json`
    beside it: classes, accuracy on every protocol test window, chance level (the most frequent
    test class), training steps, seed, training seconds. Training windows are drawn uniformly over
    every start frame of every training sequence (canonicalised for marker data), with the
    labels of `window_labels`. Progress and the accuracy go to `log`.
    """
    if not has_action_labels(ds):
        return None
    frames, canon = split_frames(ds, "train")
    _, seq_index, starts = _all_windows(ds, "train")
    train_labels = window_labels(ds, seq_index, starts, "train")
    if train_labels is None or not len(train_labels):
        return None
    classes = tuple(str(c) for c in np.unique(train_labels))
    if len(classes) < 2:
        if log is not None:
            log(f"action classifier ({ds.name}): one class only ({classes}); no FID")
        return None
    index = {c: i for i, c in enumerate(classes)}
    test_y, test_seq, test_starts = _test_futures(ds)
    test_labels = window_labels(ds, test_seq, test_starts, "test")
    unknown = sorted(set(map(str, test_labels)) - set(classes))
    if unknown:
        raise ValueError(f"action classifier ({ds.name}): test classes {unknown} have no training window (classes {list(classes)})")
    model = ac.make_model(len(classes), config)
    key = _cache_key(ds, config, frames, train_labels, test_y, test_labels)
    folder = Path(cache_dir).expanduser() if cache_dir is not None else classifier_cache_dir()
    stem = folder / f"{ds.name}_{key}"
    weights, meta = stem.with_suffix(".msgpack"), stem.with_suffix(".json")
    if weights.is_file() and meta.is_file():
        try:
            info = json.loads(meta.read_text())
            template = jax.eval_shape(model.init, jax.random.key(0), np.zeros((1, 1, ds.dim), np.float32))
            params = serialization.from_bytes(jax.tree.map(lambda s: np.zeros(s.shape, s.dtype), template), weights.read_bytes())
            if log is not None:
                log(f"action classifier ({ds.name}): cached {weights} (test accuracy {info['accuracy']:.3f}, {len(classes)} classes)")
            return TrainedClassifier(model, params, classes, info)
        except Exception as e:  # noqa: BLE001 - any damaged or foreign entry (msgpack, JSON, shapes): train again, overwrite it
            if log is not None:
                log(f"action classifier ({ds.name}): cached {weights} unreadable ({e}); training again")
    label_idx = np.asarray([index[str(c)] for c in train_labels], np.int32)

    def sample_batch(rng: np.random.Generator):
        pick = rng.integers(0, len(seq_index), size=config.batch_size)
        q, s = seq_index[pick], starts[pick]
        w = np.stack([frames[i][j : j + ds.t_total] for i, j in zip(q, s)])
        if canon is not None:
            w = canonicalise_windows(w, np.stack([canon[i][j] for i, j in zip(q, s)]))
        return w[:, ds.t_his :], label_idx[pick]

    if log is not None:
        log(f"action classifier ({ds.name}): training on {len(seq_index)} training windows, {len(classes)} classes, "
            f"{config.num_steps} steps (once; cached in {folder})")
    t0 = time.perf_counter()
    params = train_classifier(sample_batch, len(classes), config, log=log, name=f"action classifier ({ds.name})")
    train_s = time.perf_counter() - t0
    test_idx = np.asarray([index[str(c)] for c in test_labels])
    acc = ac.accuracy(model, params, test_y, test_idx)
    chance = float(np.bincount(test_idx, minlength=len(classes)).max() / len(test_idx))
    info = {
        "dataset": ds.name, "key": key, "classes": list(classes), "num_classes": len(classes), "accuracy": acc,
        "chance_accuracy": chance, "n_test_windows": int(len(test_idx)), "n_train_windows": int(len(seq_index)),
        "num_steps": config.num_steps, "seed": config.seed, "config": dataclasses.asdict(config),
        "train_s": round(train_s, 1), "jax_version": jax.__version__,
        "note": "the project's own classifier (jaxmotion.models.action_classifier), not BeLFusion's Human3.6M one",
    }  # fmt: skip
    if log is not None:
        log(f"action classifier ({ds.name}): test accuracy {acc:.3f} on {len(test_idx)} windows (chance {chance:.3f}), "
            f"trained in {train_s:.0f} s")
    try:
        # Written under private names and renamed, so a concurrent or interrupted run never leaves half a file.
        for path, data in ((weights, serialization.to_bytes(jax.device_get(params))), (meta, json.dumps(info, indent=1).encode())):
            write_bytes_atomic(path, data)
    except OSError as e:  # a read-only or full cache: the classifier still serves this evaluation
        if log is not None:
            log(f"action classifier ({ds.name}): could not cache it in {folder} ({e}); it will be trained again next time")
    return TrainedClassifier(model, params, classes, info)


# --------------------------------------------------------------------------------------------
# Evaluation: CMD and FID of one predictor, accumulated chunk by chunk.


class ChunkStats(NamedTuple):
    """What one chunk of predictions contributes: per-window profiles `(b, T-1)` and feature `Moments`."""

    profiles: np.ndarray
    moments: Moments


class ActionEvaluator:
    """CMD and FID of predictions against the test windows' futures `gt` with labels `labels`.

    `chunk(pred)` reduces a `(b, K, t_pred, D)` chunk to `ChunkStats` (so the K x N futures never
    exist at once); `result(parts)` returns `{"CMD", "FID"}` from the chunks of every test window,
    in order. The ground truth's features, and the classes' training references, are computed once.
    """

    def __init__(self, classifier: TrainedClassifier, gt: Float[np.ndarray, "n t d"], labels: np.ndarray,
                 reference: Mapping[str, float], batch: int = 256):  # fmt: skip
        self.classifier, self.labels, self.reference = classifier, np.asarray(labels), dict(reference)
        if self.labels.shape != (gt.shape[0],):
            raise ValueError(f"ActionEvaluator: {gt.shape[0]} ground-truth futures but labels of shape {self.labels.shape}")
        self.batch = batch
        self.gt = mean_cov(moments(classifier.features(np.asarray(gt, np.float32))))

    def summary(self) -> dict:
        """Returns what a record says of the classifier: accuracy, chance level, classes, budget, cache key."""
        keys = ("accuracy", "chance_accuracy", "num_classes", "n_test_windows", "num_steps", "seed", "key")
        return {k: self.classifier.info[k] for k in keys if k in self.classifier.info}

    def chunk(self, pred: Float[ArrayLike, "b k t d"], copies: int = 1) -> ChunkStats:
        """Returns the `ChunkStats` of `(b, K, t_pred, D)` predictions of `b` consecutive test windows.

        `copies`: each of the K futures stands for that many identical ones (a deterministic
        predictor scored on one copy, `Method.deterministic`): its features count `copies` times,
        so FID is that of the `K * copies` futures; CMD, a mean over the samples, is unchanged.
        """
        pred = np.asarray(pred, np.float32)
        if pred.shape[-1] % 3 or pred.shape[-2] < 2:
            raise ValueError(f"ActionEvaluator.chunk: expected (b, K, T >= 2, 3 * points) futures, got shape {pred.shape}")
        if copies < 1:
            raise ValueError(f"ActionEvaluator.chunk: copies must be >= 1, got {copies}")
        b, k = pred.shape[:2]
        feats = self.classifier.features(pred.reshape((b * k,) + pred.shape[2:]), self.batch * k)
        m = moments(feats)
        return ChunkStats(np.asarray(_mean_profile(jnp.asarray(pred))), Moments(m.n * copies, m.total * copies, m.outer * copies))

    def result(self, parts: list[ChunkStats]) -> dict[str, float]:
        """Returns `{"CMD", "FID"}` of the chunks that together cover every test window, in order."""
        profiles = np.concatenate([p.profiles for p in parts])
        if profiles.shape[0] != self.labels.shape[0]:
            raise ValueError(f"ActionEvaluator: chunks cover {profiles.shape[0]} windows, labels {self.labels.shape[0]}")
        m = parts[0].moments
        for p in parts[1:]:
            m = add_moments(m, p.moments)
        return {"CMD": cmd(profiles, self.labels, self.reference), "FID": frechet_distance(*mean_cov(m), *self.gt)}


def evaluator(
    ds: MotionDataset,
    gt: Float[np.ndarray, "n t d"],
    seq_index: Int[np.ndarray, " n"],
    starts: Int[np.ndarray, " n"],
    *,
    config: ClassifierConfig = ClassifierConfig(),
    batch: int = 64,
    cache_dir: str | os.PathLike | None = None,
    log: Callable[[str], None] | None = print,
) -> ActionEvaluator | None:
    """Returns the `ActionEvaluator` of test windows `(seq_index, starts)` with futures `gt`, or None without labels.

    `batch` is the number of windows per prediction chunk (`Config.eval_batch`): feature batches
    are `batch * K` futures, padded, so each K compiles once.
    """
    labels = window_labels(ds, seq_index, starts, "test")
    if labels is None:
        return None
    classifier = dataset_classifier(ds, config, cache_dir=cache_dir, log=log)
    if classifier is None:
        return None
    return ActionEvaluator(classifier, gt, labels, reference_displacement(ds), batch)
