"""Evaluators: each takes one predictor's futures, chunk by chunk in window order, and returns its metrics.

An evaluator is built once per evaluation (what it needs of the test windows is computed then);
`stream(copies)` starts one predictor's pass and returns an accumulator with `add(start, pred)`
(the `(b, K, t_pred, D)` futures of windows `[start, start + b)`) and `result() -> {name: float}`.
`copies`: each of the K futures stands for that many identical ones (a deterministic predictor
scored on one copy, `Method.deterministic`). `jaxmotion.eval.loop.evaluate` runs every predictor
through every evaluator and merges their results into one record.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from jaxmotion.eval.protocol import Deviation, WindowSets, averages, window_sets
from jaxmotion.eval.references import MMGroundTruth
from jaxmotion.eval.metrics import WindowMetricStream, mode_recall


class ProtocolMetrics:
    """APD, ADE, FDE, MMADE, MMFDE, ADE-m, FDE-m and the MM set statistics ([protocol §2][metrics])."""

    def __init__(self, gt: np.ndarray, truth: MMGroundTruth, deviation: Deviation, poses: np.ndarray | None = None):
        self.gt, self.truth, self.deviation = np.asarray(gt, np.float32), truth, deviation
        self.sets: WindowSets = window_sets(truth.sets, self.gt, truth.futures, deviation, poses)

    def stream(self, copies: int = 1):
        """Returns one predictor's accumulator: `add(start, pred)` per chunk, then `result()` (module docstring)."""
        s = WindowMetricStream(self.gt, self.sets.futures, self.sets.idx, self.sets.used, **self.truth.transfer())
        return _Accumulator(lambda start, p: s.add(p), lambda: averages(s.result(), self.sets, self.deviation))


class ModeRecall:
    """Recall of the known future modes (the synthetic data's `known_modes`), over the windows near a decision point."""

    def __init__(self, modes, threshold: float, max_boundary: int, batch: int):
        self.modes, self.threshold, self.max_boundary, self.batch = modes, threshold, max_boundary, batch

    def stream(self, copies: int = 1):
        """Returns one predictor's accumulator: `add(start, pred)` per chunk, then `result()` (module docstring)."""
        parts = []

        def add(start, p):
            # Padded to `batch` windows so that mode_recall compiles once.
            n, b, P = p.shape[0], self.batch, self.modes.modes.shape[1]
            fill = lambda a: np.concatenate([a, np.repeat(a[-1:], b - n, axis=0)])  # noqa: E731
            r, w = mode_recall(fill(p), fill(self.modes.modes[start : start + n]), np.broadcast_to(self.modes.probs, (b, P)),
                               np.ones((b, P), bool), self.threshold)
            parts.append((np.asarray(r)[:n], np.asarray(w)[:n]))

        def result():
            sel = self.modes.boundary <= self.max_boundary
            return {
                "mode_recall": float(np.concatenate([a for a, _ in parts])[sel].mean()),
                "mode_recall_weighted": float(np.concatenate([b for _, b in parts])[sel].mean()),
                "mode_threshold": self.threshold,
                "mode_windows": int(sel.sum()),
            }

        return _Accumulator(add, result)


class MethodMetrics:
    """A method's own per-window metrics (`Method.extra_metrics`), averaged over windows (NaN skipped)."""

    def __init__(self, per_window: Callable[[np.ndarray, np.ndarray], dict], gt: np.ndarray):
        self.per_window, self.gt = per_window, gt

    def stream(self, copies: int = 1):
        """Returns one predictor's accumulator: `add(start, pred)` per chunk, then `result()` (module docstring)."""
        parts = []

        def result():
            return {key: float(np.nanmean(np.concatenate([e[key] for e in parts]))) for key in (parts[0] if parts else ())}

        return _Accumulator(lambda start, p: parts.append(self.per_window(p, self.gt[start : start + p.shape[0]])), result)


class ActionMetrics:
    """CMD and FID (`action_metrics.ActionEvaluator`) of datasets with action labels."""

    def __init__(self, action):
        self.action = action

    def stream(self, copies: int = 1):
        """Returns one predictor's accumulator: `add(start, pred)` per chunk, then `result()` (module docstring)."""
        parts = []
        return _Accumulator(lambda start, p: parts.append(self.action.chunk(p, copies)), lambda: self.action.result(parts))


class _Accumulator:
    def __init__(self, add: Callable[[int, np.ndarray], None], result: Callable[[], dict]):
        self.add, self.result = add, result
