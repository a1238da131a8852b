"""How the networks run, apart from what they compute: one value the train step and the samplers receive.

A model file holds its paper's equations; how they run on a machine is `Execution`, passed in whole
by the method (`jaxmotion.methods.common.execution(cfg)`) to every model it builds. Every choice but
`precision` and `batch_norm` gives the same numbers up to the order of float sums (each fast form is
tested against the readable definition); `precision="bf16"` rounds the weight products' operands
(nn/precision.py), and `batch_norm="per_device"` normalises each device's rows by their own moments.
The A/B measurements behind each default are in benchmarks/results/optimisations.md (`benchmarks/ab.py --ab NAME`).

This module imports nothing but the standard library, so the config layer reads `PRECISIONS` from
here without loading jax.
"""

from __future__ import annotations

import dataclasses

PRECISIONS = ("float32", "bf16")  # `Config.precision`'s choices (nn/precision.py)
DECODER_BACKWARDS = ("batched", "autodiff")
BATCH_NORMS = ("global", "per_device")  # `Config.batch_norm`'s choices


@dataclasses.dataclass(frozen=True)
class Execution:
    """Execution choices of the networks; frozen and hashable, a static part of the modules that hold it."""

    # Every weight product's: "float32", or "bf16" (bfloat16 operands, float32 accumulation; nn/precision.py).
    precision: str = "float32"
    # The GRU CVAE decoder loop's backward pass (models/cvae.py, DLow and MOJO): "batched" computes each
    # weight's gradient as one product over all steps after the loop (nn/decoder_loop.py; float32 only,
    # bf16 falls back to "autodiff"); "autodiff" differentiates the loop (a product and an accumulation
    # per step and weight). benchmarks/results/optimisations.md, "Batched weight gradients of the decoder loop".
    decoder_backward: str = "batched"
    # With decoder_backward="autodiff": the loop's backward pass keeps each step's matrix products and
    # recomputes the gates' elementwise work (jax.checkpoint_policies.dots_saveable) instead of stacking
    # every intermediate of every step. DLow's and MOJO's second-stage steps (the gradient through the
    # K = 50 decoders) measured 1.12x faster, the CVAE steps unchanged. The same policy on the encoders'
    # GRU (nn/gru.py) measured slower, so it is not used there.
    decoder_remat: bool = True
    # With decoder_backward="autodiff": lax.scan's `unroll` of the differentiated loop. 4 measured within
    # the run-to-run spread (0.96x-1.07x), so the default stays 1.
    decoder_unroll: int = 1
    # The graph-convolution stacks' inner layout (DivSamp, GSPS; nn/gcn.py `GCLStack.node_major`):
    # node-major `(J, ..., F)` inside, batch-major `(..., J, F)` at the ends.
    gcn_node_major: bool = True
    # BatchNorm's training moments on several devices (DivSamp's GCNs and sampler): "global", those of the
    # whole global batch (an all-reduce per layer; every device count gives one device's numbers), or
    # "per_device", each device's own rows (PyTorch DistributedDataParallel's default without SyncBatchNorm:
    # no collective inside the step, the running statistics averaged in the step's one all-reduce). Like
    # precision, "per_device" changes the numbers (on one device the two are the same).
    batch_norm: str = "global"

    def __post_init__(self):
        if self.precision not in PRECISIONS:
            raise ValueError(f"Execution.precision must be one of {PRECISIONS}, got {self.precision!r}")
        if self.decoder_backward not in DECODER_BACKWARDS:
            raise ValueError(f"Execution.decoder_backward must be one of {DECODER_BACKWARDS}, got {self.decoder_backward!r}")
        if self.batch_norm not in BATCH_NORMS:
            raise ValueError(f"Execution.batch_norm must be one of {BATCH_NORMS}, got {self.batch_norm!r}")
        if isinstance(self.decoder_unroll, bool) or not isinstance(self.decoder_unroll, int) or self.decoder_unroll < 1:
            raise ValueError(f"Execution.decoder_unroll must be an integer >= 1, got {self.decoder_unroll!r}")
        for name in ("decoder_remat", "gcn_node_major"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"Execution.{name} must be True or False, got {getattr(self, name)!r}")
