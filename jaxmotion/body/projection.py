"""Recursive projection (MOJO Sec. 3.4): keep every predicted frame a valid body while decoding.

After each decoder step the predicted markers are replaced by the markers of a body model fitted
to them (MOJO Eq. (2)), and the fitted markers are what the decoder sees at the next step. Here the
whole loop is one `lax.scan` (decoder step -> Levenberg-Marquardt fit warm-started from the
previous frame's fit, shape fixed -> feed back), vmapped over K samples, under one jit:

    step = lambda carry, inp: my_decoder_step(carry, inp)            # unbatched: frame (M*3,)
    out = project_k(step, fit, carry0_k, inputs_k, init_params)      # K leading on carry/inputs

`decode_step(carry, inputs) -> (carry, frame)` is any decoder step whose frame is the flattened
markers `(..., M*3)`: unbatched `(M*3,)`, or batched `(K, M*3)` like MOJO's `decode_step`, in
which case the fit is vmapped over the batch and `init` carries the same leading axes.
`feed_back(carry, frame) -> carry` puts the fitted frame where the decoder keeps its previous
output (default: the field `y_prev` of a NamedTuple carry such as MOJO's `DecodeCarry`, else the
last element of a tuple carry `(h, y_prev)`).

    carry0, inputs = mojo.decode_inputs(dparams, x_k, z_k)            # batch = K samples
    out = recursive_projection(lambda c, i: mojo.decode_step(dparams, c, i), fit, carry0, inputs, init_k)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxmotion.body.fit import FitResult, fit_markers, fit_sequence
from jaxmotion.body.params import BodyParams


class Projection(NamedTuple):
    """Per predicted frame: the decoder's raw frame, the fitted markers and parameters, residuals."""

    raw: Float[Array, "t ... d"]
    markers: Float[Array, "t ... d"]  # fitted markers, flattened like the decoder's frames
    params: BodyParams  # leading axes (t, ...)
    residual: Float[Array, "t ... m"]  # distance raw -> fitted per marker (metres)


def replace_last(carry, frame):
    """Returns the carry with its previous output (`y_prev` field, else last element) set to `frame`."""
    if hasattr(carry, "_replace") and "y_prev" in carry._fields:
        return carry._replace(y_prev=frame.astype(carry.y_prev.dtype))
    return type(carry)((*carry[:-1], frame.astype(carry[-1].dtype)))


def body_fit_fn(body, **fit_kwargs) -> Callable[[Float[Array, "m 3"], BodyParams], FitResult]:
    """Returns `fit(targets, init) -> FitResult` for `recursive_projection` (no Kabsch re-alignment:
    the previous frame's fit is already close)."""
    fit_kwargs.setdefault("align", False)
    return lambda targets, init: fit_markers(body, targets, init, **fit_kwargs)


def recursive_projection(
    decode_step: Callable[[Any, Any], tuple[Any, Float[Array, " d"]]],
    fit: Callable[[Float[Array, "m 3"], BodyParams], FitResult],
    carry0: Any,
    inputs: Any,
    init: BodyParams,
    *,
    feed_back: Callable[[Any, Float[Array, " d"]], Any] = replace_last,
    length: int | None = None,
) -> Projection:
    """Returns the projected sequence: scan of decoder step -> body fit -> fitted markers fed back.

    `inputs` is scanned over (leading axis = time; None with `length` for an input-free decoder).
    `init` is the body fitted to the last observed frame; its shape stays fixed unless `fit` frees it.
    """

    def fit_frame(frame, prev):
        f = fit(frame.reshape(-1, 3), prev)
        return f.markers.reshape(frame.shape), f.params, jnp.linalg.norm(frame.reshape(-1, 3) - f.markers, axis=-1)

    def step(state, inp):
        carry, prev = state
        carry, frame = decode_step(carry, inp)
        fit_b = fit_frame
        for _ in range(frame.ndim - 1):  # batched decoders: one independent fit per sample
            fit_b = jax.vmap(fit_b)
        fitted, params, res = fit_b(frame, prev)
        carry = feed_back(carry, fitted)
        return (carry, params), (frame, fitted, params, res)

    _, (raw, fitted, params, res) = jax.lax.scan(step, (carry0, init), inputs, length=length)
    return Projection(raw, fitted, params, res)


def project_k(decode_step, fit, carry0_k, inputs_k, init: BodyParams, **kwargs) -> Projection:
    """Returns `recursive_projection` vmapped over K samples (leading axis of `carry0_k`, `inputs_k`).

    `init` is shared by the K samples (they continue the same observed past).
    """
    run = lambda c, i: recursive_projection(decode_step, fit, c, i, init, **kwargs)  # noqa: E731
    return jax.vmap(run)(carry0_k, inputs_k)


def init_from_observed(body, observed: Float[Array, "t m 3"], mask=None, **fit_kwargs) -> BodyParams:
    """Returns the body fitted to the last observed frame, with shape fitted over all observed frames.

    Frames are fitted in sequence with shape free (stages global, body, shape); the shape is the
    mean over frames, then the last frame is refitted with that shape fixed.
    """
    stages = ("global", "body", "shape")
    fits = fit_sequence(body, observed, body.zero_params(), mask, stages=stages, **fit_kwargs)
    shape = jnp.mean(fits.params.shape, axis=0)
    last = jax.tree.map(lambda a: a[-1], fits.params)._replace(shape=shape)
    m = None if mask is None else mask[-1]
    return fit_markers(body, observed[-1], last, m, **fit_kwargs).params
