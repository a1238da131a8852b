"""The job behind the `jaxmotion` command: data -> train a method -> protocol evaluation -> report.

Every step is also callable from Python. A work directory holds one folder per training stage
(`cvae/`, `dlow_k50/`, ... each with `ckpt/` and `log.jsonl`), `metrics.json` (PROTOCOL sec. 5
records, one per (method, K)) and `samples.png` (observed motion and K predicted futures).
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import platform
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.config import Config, to_dict
from jaxmotion.data.types import MotionDataset
from jaxmotion.data.windows import TrainSampler, canonicalise_windows, split_frames, test_windows

Predictor = Callable[[jax.Array, jax.Array], jax.Array]  # (x (b, t_his, D), key) -> (b, K, t_pred, D)

# Method name -> module providing train / restore / predictors (see jaxmotion/train/dlow.py).
METHODS = {"dlow": "jaxmotion.train.dlow", "divsamp": "jaxmotion.train.divsamp", "mojo": "jaxmotion.train.mojo"}


def get_method(name: str):
    """Returns the module implementing method `name`."""
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; known: {sorted(METHODS)}")
    return importlib.import_module(METHODS[name])


def load_data(cfg: Config, data: str | None = None) -> MotionDataset:
    """Returns the dataset named by `data` (a path) or else by `cfg.dataset` ("synthetic" or a path).

    `cfg.data_options` go to the loader (e.g. `{"markers": "bandai"}`: Bandai-Namco-2 as markers).
    """
    spec = data or cfg.dataset
    if spec == "synthetic":
        from jaxmotion.data.synthetic import make_synthetic

        if cfg.data_options:
            raise ValueError(f"the synthetic dataset takes no data_options, got {sorted(cfg.data_options)}")
        return make_synthetic(cfg.seed)
    from jaxmotion.data.datasets import load_dataset

    return load_dataset(spec, **dict(cfg.data_options))


@dataclasses.dataclass
class Prepared:
    """Frame vectors for training and the protocol test windows of one dataset."""

    dataset: MotionDataset
    sampler: TrainSampler
    windows: np.ndarray  # (N, t_total, D)
    seq_index: np.ndarray
    starts: np.ndarray
    keep: np.ndarray  # indices of these windows among all protocol test windows

    @property
    def x(self) -> np.ndarray:
        return self.windows[:, : self.dataset.t_his]

    @property
    def y(self) -> np.ndarray:
        return self.windows[:, self.dataset.t_his :]


def prepare(ds: MotionDataset, max_test_windows: int | None = None) -> Prepared:
    """Returns train sampler and test windows (PROTOCOL sec. 3: test stride t_his, random train starts).

    Marker datasets' windows are canonicalised at their first frame (PROTOCOL sec. 4).
    """
    train, train_canon = split_frames(ds, "train")
    sampler = TrainSampler(train, ds.t_total, train_canon)
    test, test_canon = split_frames(ds, "test")
    windows, seq_index, starts = test_windows(test, ds.t_his, ds.t_pred)
    if test_canon is not None:
        windows = canonicalise_windows(windows, np.stack([test_canon[i][s] for i, s in zip(seq_index, starts)]))
    keep = np.arange(len(windows))
    if max_test_windows is not None and len(windows) > max_test_windows:
        # Evenly spaced, so a quick evaluation still covers every test sequence.
        keep = np.linspace(0, len(windows) - 1, max_test_windows).round().astype(int)
        windows, seq_index, starts = windows[keep], seq_index[keep], starts[keep]
    return Prepared(ds, sampler, windows, seq_index, starts, keep)


def predict_chunks(fn: Predictor, x: np.ndarray, key: jax.Array, batch: int):
    """Yields `(b, K, t_pred, D)` numpy predictions over `x` in fixed-size (padded) batches."""
    n = x.shape[0]
    for i, s in enumerate(range(0, n, batch)):
        xb = x[s : s + batch]
        c = xb.shape[0]
        if c < batch:
            xb = np.concatenate([xb, np.repeat(xb[-1:], batch - c, axis=0)])
        yield np.asarray(fn(jnp.asarray(xb), jax.random.fold_in(key, i)))[:c]


def evaluate(cfg: Config, prep: Prepared, params, workdir: Path, data_label: str | None = None) -> list[dict]:
    """Returns and writes (`workdir/metrics.json`) one PROTOCOL sec. 5 record per (method, K)."""
    from jaxmotion import metrics

    ds = prep.dataset
    modes = None
    if ds.name == "synthetic":
        from jaxmotion.data.synthetic import test_modes

        modes = test_modes(ds)
        sel = prep.keep
        modes = modes._replace(modes=modes.modes[sel], true_mode=modes.true_mode[sel], boundary=modes.boundary[sel])
    x, y = prep.x, prep.y
    mm_sets = metrics.multimodal_gt(x[:, -1], ds.mm_threshold)
    records = []
    # Optional method hook `extra_metrics(ds, pred, gt) -> {name: (n,) per-window array}`.
    extra_fn = getattr(get_method(cfg.method), "extra_metrics", None)
    for k in cfg.eval_k:
        for name, fn in get_method(cfg.method).predictors(cfg, ds, params, k).items():
            t0 = time.perf_counter()
            recalls, extras = [], []

            def chunks():
                for i, p in enumerate(predict_chunks(fn, x, jax.random.key(cfg.seed + 7), cfg.eval_batch)):
                    if modes is not None:
                        sl = slice(i * cfg.eval_batch, i * cfg.eval_batch + p.shape[0])
                        n, P = p.shape[0], modes.modes.shape[1]
                        r, w = metrics.mode_recall(
                            p, modes.modes[sl], np.broadcast_to(modes.probs, (n, P)), np.ones((n, P), bool), cfg.mode_threshold
                        )
                        recalls.append((np.asarray(r), np.asarray(w)))
                    if extra_fn is not None:
                        extras.append(extra_fn(ds, p, y[i * cfg.eval_batch : i * cfg.eval_batch + p.shape[0]]))
                    yield p

            m = metrics.evaluate_windows(chunks(), y, mm_sets, mm_deviation=cfg.mm_deviation)
            m.pop("n_windows")  # a top-level field of the record (PROTOCOL sec. 5)
            if modes is not None:
                sel = modes.boundary <= cfg.mode_max_boundary
                r = np.concatenate([a for a, _ in recalls])[sel]
                w = np.concatenate([b for _, b in recalls])[sel]
                m["mode_recall"] = float(r.mean())
                m["mode_recall_weighted"] = float(w.mean())
                m["mode_threshold"] = cfg.mode_threshold
                m["mode_windows"] = int(sel.sum())
            for key in extras[0] if extras else ():
                m[key] = float(np.nanmean(np.concatenate([e[key] for e in extras])))
            wall = time.perf_counter() - t0
            rec = {
                "dataset": data_label or ds.name,
                "method": name,
                "K": k,
                "n_windows": int(len(x)),
                "metrics": m,
                "seed": cfg.seed,
                "config": to_dict(cfg),
                "jax_version": jax.__version__,
                "device": f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind} ({platform.machine()})",
                "wall_s": round(wall, 3),
            }
            records.append(rec)
            print(format_record(rec), flush=True)
    workdir.mkdir(parents=True, exist_ok=True)
    with open(workdir / "metrics.json", "w") as f:
        json.dump(records, f, indent=1, default=float)
    return records


def format_record(rec: dict) -> str:
    m = rec["metrics"]
    keys = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "mode_recall", "mode_recall_weighted"]
    vals = " ".join(f"{k}={m[k]:.4f}" for k in keys if k in m)
    return f"[{rec['dataset']}] {rec['method']:<13s} K={rec['K']:<3d} {vals} ({rec['wall_s']:.1f}s)"


def report(cfg: Config, prep: Prepared, params, workdir: Path, method: str | None = None) -> Path:
    """Writes `workdir/samples.png` for the test window whose ground truth is most multimodal.

    That is the window whose multimodal ground-truth futures (PROTOCOL sec. 2) end furthest apart
    on average: where a good stochastic predictor should show several distinct futures.
    """
    from jaxmotion import metrics
    from jaxmotion.viz import plot_futures

    ds = prep.dataset
    k = max(cfg.eval_k)
    idx, mask = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold)
    idx, mask = np.asarray(idx), np.asarray(mask)
    ends = prep.y[:, -1]
    spread = (np.linalg.norm(ends[idx] - ends[:, None], axis=-1) * mask).sum(1) / mask.sum(1)
    i = int(np.argmax(spread))
    method = method or cfg.method
    fn = get_method(cfg.method).predictors(cfg, ds, params, k)[method]
    preds = np.asarray(fn(jnp.asarray(prep.x[i : i + 1]), jax.random.key(cfg.seed + 11)))[0]
    title = (
        f"{ds.name}: test window {i} (sequence {prep.seq_index[i]}, start frame {prep.starts[i]}), "
        f"{method}, K={k}, {ds.t_his} observed -> {ds.t_pred} predicted frames at {ds.fps:g} fps"
    )
    return plot_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, workdir / "samples.png", title=title)
