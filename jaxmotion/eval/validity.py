"""Pose validity of any method's predictions under a trained GSPS run: angle-limit violations and pose-prior NLL.

GSPS (Mao, Liu & Salzmann, ICCV 2021, Sec. 3.2-3.3) judges a predicted pose by two learned facts
about the training poses, both of which depend only on the frames and the skeleton, so they score
every method's predictions on that skeleton alike:

* **Angle limits**: the cosines between limb vectors and body planes (`models.gsps.angle_cosines`)
  against the `[lo, hi]` bounds of the run's `angle_bounds` stage (a bound applies only where
  `lo >= -0.98` / `hi <= 0.98`). `angle_violation` is the fraction of predicted frames with at
  least one cosine outside its bounds.
* **Pose prior**: the negative log-density of a frame's unit limb directions under the run's
  normalizing flow (its `prior` stage), `prior_nll = -log N(f(d); 0, I) - log |det df/dd|`, in nats
  per frame. `prior_nll_z = -log N(f(d); 0, I)` leaves out the log-determinant, as the release's
  `eval.py` (`compute_pz`) reports it; the two differ by a PReLU term that depends on the pose.

    v = validity.from_gsps_run(gsps_cfg, ds, gsps_params)     # or PoseValidity(...) by hand
    per_window = validity.window_validity(v, pred)            # {"angle_violation": (n,), "prior_nll": (n,), ...}

`experiments/validity_table.py` applies it to every trained run beside APD / ADE.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.eval import realism
from jaxmotion.models import gsps


class PoseValidity(NamedTuple):
    """What scores a pose: the skeleton, the angle bounds and a trained pose prior (with its parameters)."""

    names: tuple[str, ...]  # joint names, root first (the skeleton's)
    parents: tuple[int, ...]
    bounds: Float[np.ndarray, "a 2"]  # (len(models.gsps.ANGLE_NAMES), 2) cosine bounds [lo, hi]
    prior: gsps.PosePrior
    prior_params: Any


def from_gsps_run(cfg, ds, params: dict) -> PoseValidity:
    """Returns the `PoseValidity` of a trained GSPS run: its skeleton, its `angle_bounds` stage and its `prior` stage."""
    # The settings are read here, not through `methods.gsps.settings`: methods import this module (layers import one way).
    mc = cfg.method_config if cfg.method_config is not None else gsps.GSPSConfig()
    if not isinstance(mc, gsps.GSPSConfig):
        raise TypeError(f"from_gsps_run: config {cfg.name!r} is not a GSPS run's (method_config {type(mc).__name__})")
    c = mc  # a GSPSConfig checks itself when made
    return PoseValidity(
        names=tuple(ds.skeleton.names), parents=tuple(int(p) for p in ds.skeleton.parents),
        bounds=np.asarray(params["angle_bounds"]["bounds"], np.float32),
        prior=gsps.PosePrior(dim=ds.dim, n_layers=c.prior_layers), prior_params=params["prior"],
    )


def check_skeleton(v: PoseValidity, names, parents, what: str) -> None:
    """Raises a ValueError when `what`'s skeleton is not the one `v` was trained on (the scores would be meaningless)."""
    if tuple(names) != v.names or tuple(int(p) for p in parents) != v.parents:
        raise ValueError(
            f"{what}: its skeleton ({len(names)} joints: {list(names)[:4]}...) is not the GSPS run's "
            f"({len(v.names)} joints: {list(v.names)[:4]}...); angle bounds and pose prior apply only to that skeleton"
        )


@functools.partial(jax.jit, static_argnames=("prior", "parents", "roles"))
def _scores(prior_params, bounds, frames, *, prior, parents, roles):
    viol = gsps.violation_fraction(frames, dict(roles), bounds)  # (..., K) over time
    z, logdet = prior.apply(prior_params, gsps.limb_directions(frames, parents))
    nll_z = -gsps.std_normal_log_prob(z)  # (..., K, t)
    return viol, jnp.mean(nll_z - logdet, axis=-1), jnp.mean(nll_z, axis=-1)


def sample_validity(v: PoseValidity, pred: Float[ArrayLike, "n k t d"]) -> dict[str, Float[Array, "n k"]]:
    """Returns per sample `(n, K)`: `angle_violation` (fraction of its frames), `prior_nll` and `prior_nll_z` (mean per frame)."""
    frames = jnp.asarray(pred, jnp.float32)
    if frames.ndim != 4 or frames.shape[-1] != 3 * (len(v.names) - 1):
        raise ValueError(f"sample_validity: pred must be (n, K, t_pred, {3 * (len(v.names) - 1)}), got {tuple(frames.shape)}")
    roles = tuple(sorted(gsps.angle_roles(v.names, v.parents).items()))
    viol, nll, nll_z = _scores(v.prior_params, jnp.asarray(v.bounds), frames, prior=v.prior, parents=v.parents, roles=roles)
    return {"angle_violation": viol, "prior_nll": nll, "prior_nll_z": nll_z}


def window_validity(v: PoseValidity, pred: Float[ArrayLike, "n k t d"], *, bdf: bool = True) -> dict[str, np.ndarray]:
    """Returns per window `(n,)`, each averaged over the K samples: `angle_violation`, `prior_nll`, `prior_nll_z`,
    and (with `bdf`, where the skeleton names its limb joints) `BDF`, the bone deformation of `realism.bone_deformation`."""
    out = {k: np.asarray(jnp.mean(a, axis=-1)) for k, a in sample_validity(v, pred).items()}
    if bdf:
        try:
            out["BDF"] = np.asarray(jnp.mean(realism.bone_deformation(jnp.asarray(pred, jnp.float32), v.names[1:]), axis=-1))
        except ValueError:  # no known limb-bone naming: no BDF
            pass
    return out


def bounds_record(bounds: Float[ArrayLike, "a 2"]) -> dict[str, list[float]]:
    """Returns `{angle name: [lo, hi]}` (4 decimals): the bounds as metrics.json records them."""
    return {name: [round(float(lo), 4), round(float(hi), 4)] for name, (lo, hi) in zip(gsps.ANGLE_NAMES, np.asarray(bounds))}
