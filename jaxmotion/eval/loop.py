"""The evaluation of a trained method: every predictor at every K through every evaluator ([protocol §6][reporting] records).

`evaluate` builds the evaluators once (the multimodal ground truth of `Config.mm_ground_truth`
or the method's own, the deviation of `Config.mm_deviation`, mode recall where the dataset knows
its futures' modes, the method's own metrics, CMD / FID where it has action labels), then runs
each predictor's futures through all of them, chunk by chunk, into one record per (predictor, K).
`learning_curve` scores a training run's predictors the same way on a fixed subset of windows.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from pathlib import Path

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxmotion.eval import action_metrics
from jaxmotion.train import distributed
from jaxmotion.train.compile_time import CompileTimer
from jaxmotion.config import Config, to_dict
from jaxmotion.data.prepare import Prepared
from jaxmotion.eval.evaluators import ActionMetrics, MethodMetrics, ModeRecall, ProtocolMetrics
from jaxmotion.eval.protocol import PROTOCOL, deviation, multi_future_windows
from jaxmotion.eval.references import reference
from jaxmotion.formats.atomic import write_text_atomic
from jaxmotion.method import Method, Predictor

CURVE_METRICS = ("APD", "ADE", "FDE", "MMADE", "MMFDE")


def mm_source(cfg: Config, method: Method) -> str:
    """Returns the name of the MM ground truth `cfg`'s evaluation uses: `cfg.mm_ground_truth`, else the method's own."""
    return cfg.mm_ground_truth or method.reference_futures


def predict_chunks(fn: Predictor, x: np.ndarray, key: jax.Array, batch: int, *, mesh: Mesh | None = None):
    """Yields `(b, K, t_pred, D)` numpy predictions over `x` in fixed-size (padded) batches of `batch` windows.

    Each batch is split over the devices of `mesh` (default `distributed.data_mesh()`: every device
    of every process), each predicting its share of the windows; a batch is padded to a multiple of
    the device count. With several processes every one calls this alike and receives every prediction.
    """
    mesh = distributed.data_mesh() if mesh is None else mesh
    sharding = NamedSharding(mesh, PartitionSpec("data"))
    size = -(-batch // mesh.size) * mesh.size
    n = x.shape[0]
    for i, s in enumerate(range(0, n, batch)):
        xb = x[s : s + batch]
        c = xb.shape[0]
        if c < size:
            xb = np.concatenate([xb, np.repeat(xb[-1:], size - c, axis=0)])
        out = fn(distributed.global_batch(xb, sharding), jax.random.fold_in(key, i))
        yield distributed.gather(out)[:c]


def action_evaluator(cfg: Config, prep: Prepared) -> action_metrics.ActionEvaluator | None:
    """Returns the CMD / FID evaluator of `prep`'s test windows, or None without labels.

    The classifier is trained once per dataset at `cfg.action_classifier_steps` and cached
    (`jaxmotion.eval.action_metrics`); its feature batches follow `cfg.eval_batch`.
    """
    c = action_metrics.ClassifierConfig(num_steps=cfg.action_classifier_steps)
    return action_metrics.evaluator(prep.dataset, prep.y, prep.seq_index, prep.starts, config=c, batch=cfg.eval_batch)


def select_windows(prep: Prepared, sel: np.ndarray) -> Prepared:
    """Returns `prep` with only the test windows `sel` (indices `(n,)`)."""
    return dataclasses.replace(prep, windows=prep.windows[sel], seq_index=prep.seq_index[sel], starts=prep.starts[sel],
                               keep=prep.keep[sel])


def evaluators(cfg: Config, method: Method, prep: Prepared, params: dict) -> tuple[Prepared, list, dict]:
    """Returns `(the windows scored, the evaluators, fields for every record's config)` of `cfg`'s evaluation."""
    ds, source, dev = prep.dataset, mm_source(cfg, method), deviation(cfg.mm_deviation)
    if dev.needs_test_sets and source != "test":
        raise ValueError(f"mm_deviation={dev.name!r} needs test-window reference futures; the MM ground truth here is {source!r}")
    if dev.skips_windows:  # the windows it skips enter no metric; the others are scored by the protocol
        prep, dev = select_windows(prep, multi_future_windows(prep.x[:, -1], ds.mm_threshold)), PROTOCOL
    truth = reference(source).build(prep)
    out = [ProtocolMetrics(prep.y, truth, dev, poses=prep.x[:, -1])]
    if ds.known_modes is not None:
        modes = ds.known_modes(ds)
        sel = prep.keep
        modes = modes._replace(modes=modes.modes[sel], true_mode=modes.true_mode[sel], boundary=modes.boundary[sel])
        out.append(ModeRecall(modes, cfg.mode_threshold, cfg.mode_max_boundary, cfg.eval_batch))
    fields = {}
    if method.extra_metrics is not None:
        extra = method.extra_metrics(cfg, ds, params)
        out.append(MethodMetrics(extra.per_window, prep.y))
        fields.update(extra.record)
    action = action_evaluator(cfg, prep) if cfg.action_metrics else None
    if action is not None:
        out.append(ActionMetrics(action))
        fields["action_classifier"] = action.summary()
    return prep, out, fields


def evaluate(cfg: Config, method: Method, prep: Prepared, params: dict, workdir: Path, data_label: str | None = None) -> list[dict]:
    """Returns and writes (`workdir/metrics.json`) one [protocol §6][reporting] record per (predictor, K).

    `cfg` is resolved (its `method_config` checked, `experiment.resolve`); `method` is its method.
    """
    ds = prep.dataset
    source = mm_source(cfg, method)
    prep, evs, fields = evaluators(cfg, method, prep, params)
    records = []
    for k in cfg.eval_k:
        for name, fn in method.predictors(cfg, ds, params, k).items():
            t0 = time.perf_counter()
            # K copies of one future: scored on one copy, every metric unchanged (`Method.deterministic`).
            copies = k if name in method.deterministic else 1
            streams = [e.stream(copies) for e in evs]
            with CompileTimer() as compiling:  # the predictor's first call, and the metrics' at a new K, compile
                for i, p in enumerate(predict_chunks(fn, prep.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)):
                    p = p[:, :1] if copies > 1 else p
                    for s in streams:
                        s.add(i * cfg.eval_batch, p)
                m = {}
                for s in streams:
                    m.update(s.result())
            m.pop("n_windows")  # a top-level field of the record (protocol §6 (docs/pages/protocol.md#reporting))
            rec = {
                "dataset": data_label or ds.name,
                "method": name,
                "K": k,
                "n_windows": int(len(prep.windows)),
                "metrics": m,
                "mm_source": source,  # where MMADE / MMFDE's ground truth came from (`jaxmotion.eval.references`)
                "seed": cfg.seed,
                "config": {**to_dict(cfg), **fields},
                "jax_version": jax.__version__,
                "device": f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind} ({platform.machine()})",
                "devices": jax.device_count(),  # every process's (jaxmotion train --host-devices, jax.distributed)
                "wall_s": round(time.perf_counter() - t0, 3),
                "compile_s": round(compiling.seconds, 3),  # part of wall_s: tracing + XLA compilation
            }
            records.append(rec)
            print(format_record(rec), flush=True)
    workdir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(workdir / "metrics.json", json.dumps(records, indent=1, default=float))
    return records


def format_record(rec: dict) -> str:
    """Returns one line of a record's main metrics, as `jaxmotion eval` prints them."""
    m = rec["metrics"]
    keys = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "FFE", "mode_recall", "mode_recall_weighted", "CMD", "FID"]
    vals = " ".join(f"{k}={m[k]:.4f}" for k in keys if k in m)
    compiling = f", {rec['compile_s']:.1f}s compiling" if "compile_s" in rec else ""
    return f"[{rec['dataset']}] {rec['method']:<13s} K={rec['K']:<3d} {vals} ({rec['wall_s']:.1f}s{compiling})"


def learning_curve(cfg: Config, method: Method, prep: Prepared):
    """Returns `curve(params) -> {"K", "n_windows", "predictors": {name: {APD, ADE, FDE, MMADE, MMFDE}}} | None`.

    The windows are `cfg.curve_windows` evenly spaced test windows (the same at every point); their
    MM sets come from the evaluation's source (`mm_source`) built over every window of that source
    (`mm_deviation` not applied), so the multimodal terms are the full evaluation's for those
    windows. The predictors are those the method's trained stages allow (`Method.predictors` with
    the stages trained so far), less `Method.curve_skip`; None when that leaves none. The noise key
    is the same at every point.
    """
    ds, n = prep.dataset, len(prep.windows)
    sub = np.unique(np.linspace(0, n - 1, min(cfg.curve_windows, n)).round().astype(int))
    truth = reference(mm_source(cfg, method)).build(prep).rows(sub)
    if truth.futures is None:  # the test windows' sets index every test window's future, not only `sub`'s
        truth = truth._replace(futures=prep.y)
    protocol = ProtocolMetrics(prep.y[sub], truth, PROTOCOL)
    x = prep.x[sub]

    def curve(params: dict) -> dict | None:
        out = {}
        for name, fn in method.predictors(cfg, ds, params, cfg.curve_k).items():
            if name in method.curve_skip:
                continue
            s = protocol.stream()
            for i, p in enumerate(predict_chunks(fn, x, jax.random.key(cfg.seed + 11), cfg.eval_batch)):
                s.add(i * cfg.eval_batch, p)
            m = s.result()
            out[name] = {k: round(float(m[k]), 6) for k in CURVE_METRICS}
        return {"K": cfg.curve_k, "n_windows": int(len(sub)), "predictors": out} if out else None

    return curve
