"""Evaluation ([protocol §2][metrics] and [protocol §6][reporting]): the metrics' references, the protocol's averages and its deviations, evaluators.

- `jaxmotion.eval.metrics`: the per-window metrics (APD, ADE, FDE, MMADE, MMFDE, ...), pure functions.
- `references`: where MMADE / MMFDE's multimodal ground truth comes from (`REFERENCES`).
- `protocol`: averages over windows, and the deviations of published code (`DEVIATIONS`);
  `evaluate_windows`, the metrics of predictions for given windows in one call.
- `evaluators`: protocol metrics, mode recall, a method's own metrics, CMD / FID, each fed chunks.
- `loop`: `evaluate` (every predictor x every evaluator -> metrics.json) and `learning_curve`.
"""

from jaxmotion.eval.loop import evaluate, format_record, learning_curve, mm_source, predict_chunks
from jaxmotion.eval.protocol import DEVIATIONS, Deviation, evaluate_windows, reduce_mm
from jaxmotion.eval.references import REFERENCES, MMGroundTruth, reference

__all__ = ["evaluate", "format_record", "learning_curve", "mm_source", "predict_chunks", "DEVIATIONS", "Deviation",
           "evaluate_windows", "reduce_mm", "REFERENCES", "MMGroundTruth", "reference"]
