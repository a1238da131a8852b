"""Seconds that jax spends tracing, lowering and compiling inside a block of code, from its own compile events.

    with CompileTimer() as ct:
        run_the_evaluation()
    print(ct.seconds, "s of it compiling")

The time is read from the spans jax records around each tracing, lowering to StableHLO and XLA
compilation (`jax.monitoring`, the events of `jax._src.dispatch`), so it needs no change to how
the jitted functions are called, and it covers every function first called inside the block.
Spans that overlap (a jitted function traced while another is being traced) count once.
"""

from __future__ import annotations

import jax.monitoring

COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)


def union_seconds(spans: list[tuple[float, float]]) -> float:
    """Returns the length of the union of the `(start, end)` intervals."""
    total, reach = 0.0, float("-inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


class CompileTimer:
    """Context manager whose `seconds` is the wall time inside the block spent in jax's tracing, lowering and compiling.

    NaN with a jax too old to report time spans (`jax.monitoring.register_event_time_span_listener`).
    """

    def __init__(self):
        self.spans: list[tuple[float, float]] = []
        self._register = getattr(jax.monitoring, "register_event_time_span_listener", None)
        self._unregister = getattr(jax.monitoring, "unregister_event_time_span_listener", None)

    def _listen(self, event: str, start: float, end: float, **_):
        if event in COMPILE_EVENTS:
            self.spans.append((start, end))

    def __enter__(self) -> "CompileTimer":
        if self._register and self._unregister:
            self._register(self._listen)
        return self

    def __exit__(self, *exc):
        if self._register and self._unregister:
            self._unregister(self._listen)
        return False

    @property
    def seconds(self) -> float:
        return union_seconds(self.spans) if self._register and self._unregister else float("nan")
