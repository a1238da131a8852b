"""Diversity settings scaled to a dataset's motion: the rule that relates the releases' Human3.6M and HumanEva-I values.

Diversity terms compare distances between samples with a scale that depends on how far the
body moves in a future window:

- DLow (and MOJO's per-band DLow): `exp(-||y_i - y_j||^2 / d_scale)`, a squared L2 distance over
  `t_pred x D` numbers, so `d_scale` has units of m^2;
- GSPS: `exp(-||y_i - y_j||_1 / alpha)` over a body part's `t_pred x coords` numbers (`beta` for
  the later parts), so `alpha` and `beta` are metres.

The same value therefore means a different spread on every dataset. The releases tuned them by
hand per dataset; their values relate to the motion through one statistic, the **future spread**
`s`: the zero-velocity ADE of the windows ([protocol §2][metrics]: the mean over future frames of the
Euclidean norm, over the whole D-vector, of the frame minus the last observed frame). Per
coordinate that is `sigma = s / sqrt(D)`, and each setting is the number of distances its term
sums times the matching power of `sigma`:

    d_scale = c_dlow  * t_pred * D            * sigma^2   (= c_dlow * t_pred * s^2)
    alpha   = c_first * t_pred * coords_first * sigma
    beta    = c_rest  * t_pred * coords_rest  * sigma

Each constant is the geometric mean of what the two releases imply (`RELEASES`; their `s` is the
zero-velocity ADE the papers report on the test split, the only documented figure). The releases
themselves follow the rule only loosely (`release_factors`: DLow's `d_scale` within 1.13x, GSPS's
`beta` within 1.42x and its `alpha` within 1.67x of the rule): the rule gives a starting point on
a new dataset that a validation sweep then refines, not a substitute for one. A dataset's own `s`
is measured on its training windows (`future_spread`), never on its test windows.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from jaxtyping import Float


@dataclasses.dataclass(frozen=True)
class ReleaseSettings:
    """One release's dataset shape, its documented future spread and its hand-tuned diversity settings."""

    dataset: str
    t_pred: int
    dim: int  # D: root-relative joints x 3
    coords_first: int  # GSPS's first part (lower body) coordinates
    coords_rest: int  # GSPS's later part coordinates
    spread: float  # zero-velocity ADE (metres, norm over the D-vector), as published for the test split
    d_scale: float  # DLow
    alpha: float  # GSPS, first part
    beta: float  # GSPS, later parts


# DLow's `h36m_nsamp50.yml` / `humaneva_nsamp50.yml` d_scale; GSPS's `h36m.yml` / `humaneva.yml` alphas
# and parts (H36M: joints 0-5 then 6-15; HumanEva-I: joints 7-12 then the other 8); zero-velocity
# ADE as published (BeLFusion, Table 1).
RELEASES = (
    ReleaseSettings("h36m", t_pred=100, dim=48, coords_first=18, coords_rest=30, spread=0.597, d_scale=100.0, alpha=100.0, beta=300.0),
    ReleaseSettings("humaneva", t_pred=60, dim=42, coords_first=18, coords_rest=24, spread=0.387, d_scale=20.0, alpha=15.0, beta=50.0),
)


def _implied(r: ReleaseSettings) -> dict[str, float]:
    """Returns the constants one release implies: its setting divided by the rule's data term."""
    sigma = r.spread / math.sqrt(r.dim)
    return {
        "dlow": r.d_scale / (r.t_pred * r.dim * sigma**2),
        "first": r.alpha / (r.t_pred * r.coords_first * sigma),
        "rest": r.beta / (r.t_pred * r.coords_rest * sigma),
    }


def _geometric_mean(values) -> float:
    values = list(values)
    return math.exp(sum(math.log(v) for v in values) / len(values))


CONSTANTS = {k: _geometric_mean(_implied(r)[k] for r in RELEASES) for k in ("dlow", "first", "rest")}


def release_factors() -> dict[str, dict[str, float]]:
    """Returns, per release, how far its own setting is from the rule's value (setting / rule, per constant)."""
    return {r.dataset: {k: v / CONSTANTS[k] for k, v in _implied(r).items()} for r in RELEASES}


def future_spread(windows: Float[np.ndarray, "n t d"], t_his: int) -> float:
    """Returns the zero-velocity ADE (metres) of `(N, t_his + t_pred, D)` windows: `mean ||y_t - x_last||` over windows and future frames."""
    w = np.asarray(windows, np.float64)
    if w.ndim != 3 or not 0 < t_his < w.shape[1]:
        raise ValueError(f"future_spread: need (N, T, D) windows with 0 < t_his < T, got shape {w.shape}, t_his {t_his}")
    if not np.all(np.isfinite(w)):
        raise ValueError("future_spread: windows contain NaN or inf")
    return float(np.linalg.norm(w[:, t_his:] - w[:, t_his - 1 : t_his], axis=-1).mean())


def dlow_d_scale(spread: float, t_pred: int, dim: int) -> float:
    """Returns DLow's `d_scale` (m^2) for future spread `spread` (`future_spread`), `t_pred` future frames and `dim` coordinates."""
    sigma = spread / math.sqrt(dim)
    return CONSTANTS["dlow"] * t_pred * dim * sigma**2


def gsps_alphas(spread: float, t_pred: int, dim: int, coords_first: int, coords_rest: int) -> tuple[float, float]:
    """Returns GSPS's `(alpha, beta)` (metres): the L1 scales of the first part's and the later parts' diversity terms."""
    sigma = spread / math.sqrt(dim)
    return CONSTANTS["first"] * t_pred * coords_first * sigma, CONSTANTS["rest"] * t_pred * coords_rest * sigma
