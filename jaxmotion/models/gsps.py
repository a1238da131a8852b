"""GSPS (Mao, Liu, Salzmann, ICCV 2021): a pose prior, joint-angle limits and body parts sampled in sequence.

Two networks, trained one after the other (authors' release github.com/wei-mao-2019/gsps):

* **Pose prior** (`train_nf.py`, `models/LinNF.py`): a pose is its `J - 1` unit limb directions
  `d_i = (p_i - p_parent(i)) / ||p_i - p_parent(i)||` (root dropped, `3 (J - 1)` numbers;
  `limb_directions`). A normalizing flow of three invertible layers
  `f' = PReLU(f Q R + b)`, the last without PReLU, maps them to N(0, I): Q orthogonal, a product
  of d Householder reflections; R upper triangular with a positive diagonal,
  `triu(R, 1) + diag(exp(diag R))`, so `log |det| = sum diag R`; PReLU with one learnable slope
  a (init 0.25; stored as log a so it stays positive), `log |det| = log a` per negative element.
  Trained by maximum likelihood `log p(d) = log N(f(d); 0, I) + log |det df/dd|` on single
  training frames (release: Adam lr 1e-2, weight decay 1e-3, batch 4096, 25 epochs of 200k
  frames, 5 at constant lr then linear decay).
* **Generator** (`train.py`, `models/GCN.py: GCNParts`): the history padded with its last frame
  to `t_his + t_pred`, DCT, first `n_pre` coefficients, per-joint features `[x | y | z]`
  (`jaxmotion.dct.condition_nodes`). One GCN per body part (in -> 256, BatchNorm, tanh, 4 residual
  blocks of two graph convolutions, 256 -> in, plus the input): part i sees the whole current
  body with its own 64-d noise tiled to every node, and writes back only its own joints; parts
  run in sequence (lower body, then upper body; or the five-part split). The inverse DCT gives
  the whole sequence, past included.

Objective (`generator_loss`, release `loss_function`; weights Human3.6M / HumanEva-I):
past reconstruction 100, limb length 500, lower-body diversity 8 / 5 and upper-body diversity
25 / 10 (`mean exp(-||Y_i - Y_j||_1 / alpha)` over the part's coordinates, alpha 100 / 15 for
the first part, beta 300 / 50 for the rest), best-of-nk^2 reconstruction 2, multimodal
reconstruction against pseudo ground truth 1, pose-prior NLL 0.01 on every 3rd future frame
(`-log N(f(d); 0, I)`: the release leaves the log-det term commented out), angle loss 100.

Training draws nk1 x nk2 samples per window: nk1 noises for the first part, and for each of
them nk2 noises for every later part (the release's `repeat_interleave` of the first part's noise).

Angle limits (`angle_cosines`, `angle_loss`): cosines between limb vectors and body planes, after
the release's `utils/valid_angle_check.py`, defined here from joint *roles* found by joint name
(`angle_roles`), so one definition serves Human3.6M, HumanEva-I, Bandai-Namco-2, the synthetic
data and any BVH. The release's bounds are not in its repository (it loads them from
`data/h36m_valid_angle.p` / `humaneva_valid_angle.p`, distributed separately), so the bounds
are measured from the training poses for every skeleton (`measure_angle_bounds`, percentiles
`angle_percentile` and `100 - angle_percentile`, default 0.1).
"""

from __future__ import annotations

import dataclasses
import re

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jaxmotion.nn.batch import batch_rows, batch_sum
from jaxmotion.body.bones import bone_lengths, bone_vectors
from jaxmotion.dct import condition_nodes, from_nodes
from jaxmotion.losses import pairwise_sq_distances
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.gcn import GCLStack, GraphConv

PART_SPLITS = ("lower_upper", "five")
PART_NAMES = {"lower_upper": ("lower", "upper"), "five": ("torso", "right_leg", "left_leg", "right_arm", "left_arm")}


@dataclasses.dataclass(slots=True)
class GSPSConfig:
    """GSPS's settings (`Config.method_config` of method "gsps"): the prior stage, the generator stage, the objective.

    Defaults are the release's Human3.6M configs (`h36m_nf.yml`, `h36m.yml`) except the step
    counts, which the configs under experiments/configs set per dataset.
    """

    # Pose prior (h36m_nf.yml: 3 flow layers, lr 1e-2, batch 4096, 25 epochs x 200k frames, 5 fixed).
    prior_layers: int = 3
    prior_lr: float = 1e-2
    prior_weight_decay: float = 1e-3  # torch Adam's weight_decay: an L2 term added to the gradient
    prior_batch_size: int = 4096
    prior_num_steps: int = 1220  # 25 * 200000 / 4096
    prior_lr_fix_fraction: float = 0.2
    # Generator (h36m.yml: GCN 256, 4 residual blocks, nz 64, n_pre 10, batch 16, lr 1e-3, 500 x 5000 windows).
    parts: str = "lower_upper"  # "lower_upper" (N = 2) | "five" (torso, right leg, left leg, right arm, left arm)
    n_pre: int = 10  # HumanEva-I: 8
    hidden: int = 256
    num_stage: int = 4
    nz: int = 64
    nk1: int = 10  # samples of the first part per window while training
    nk2: int = 10  # samples of the later parts per first-part sample
    lr: float = 1e-3
    batch_size: int = 16
    num_steps: int = 156250  # 500 * 5000 / 16
    lr_fix_fraction: float = 0.2
    grad_clip: float = 100.0
    # Objective (h36m.yml `lambdas`, `alphas`; HumanEva-I: div 5 / 10, alpha 15, beta 50).
    lambda_his: float = 100.0
    lambda_limb: float = 500.0
    lambda_div_first: float = 8.0
    lambda_div_rest: float = 25.0
    alpha: float = 100.0
    beta: float = 300.0
    lambda_recon: float = 2.0
    lambda_recon_mm: float = 1.0
    lambda_prior: float = 0.01
    prior_stride: int = 3  # the prior term sees every 3rd future frame (random phase)
    lambda_angle: float = 100.0
    angle_percentile: float = 0.1  # measured bounds: the 0.1th and 99.9th percentiles of the training poses,
    angle_margin: float = 0.05  # widened by this much in cosine (`measure_angle_bounds`)
    angle_bounds_frames: int = 20000  # training frames (evenly spaced) the bounds are measured on
    # Pseudo multimodal ground truth (release: candidates every 20 (H36M) / 15 (HumanEva) training
    # frames; last observed pose within 0.05 m mean per-joint distance; future at least 0.1 m /
    # 0.01 m away; 10 drawn per window).
    mm_candidate_stride: int = 20
    mm_his_threshold: float = 0.05
    mm_pred_threshold: float = 0.1
    mm_num: int = 10

    def __post_init__(self):  # the settings check themselves: a bad value fails where it is written
        check_config(self)


def check_config(c: GSPSConfig) -> GSPSConfig:
    """Returns `c` after checking it, raising a ValueError that names the bad field."""
    if not isinstance(c, GSPSConfig):
        raise TypeError(f"Config.method_config must be a jaxmotion.models.gsps.GSPSConfig, got {type(c).__name__}")
    if c.parts not in PART_SPLITS:
        raise ValueError(f"GSPSConfig.parts must be one of {PART_SPLITS}, got {c.parts!r}")
    for name in ("prior_layers", "prior_batch_size", "n_pre", "hidden", "nz", "nk1", "nk2", "batch_size", "prior_stride",
                 "mm_candidate_stride", "mm_num"):
        if getattr(c, name) < 1:
            raise ValueError(f"GSPSConfig.{name} must be >= 1, got {getattr(c, name)}")
    if c.nk1 < 2 or c.nk2 < 2:
        raise ValueError(f"GSPSConfig.nk1 and nk2 must be >= 2 (the diversity terms need pairs), got {c.nk1}, {c.nk2}")
    if not 0.0 <= c.angle_percentile < 50.0:
        raise ValueError(f"GSPSConfig.angle_percentile must be in [0, 50), got {c.angle_percentile}")
    return c


# --------------------------------------------------------------------------------------------
# Poses as limb directions.


def positions(frames: Float[Array, "... d"]) -> Float[Array, "... j 3"]:
    """Returns the `(..., J, 3)` joint positions of root-relative, root-dropped frame vectors (the root at 0)."""
    pos = frames.reshape(frames.shape[:-1] + (-1, 3))
    return jnp.concatenate([jnp.zeros_like(pos[..., :1, :]), pos], axis=-2)


def limb_directions(frames: Float[Array, "... d"], parents: tuple[int, ...]) -> Float[Array, "... d"]:
    """Returns the unit limb directions `d_i = (p_i - p_parent(i)) / ||.||`, i = 1..J-1, flattened (GSPS Sec. 3.2)."""
    v = bone_vectors(frames, parents)
    # One reciprocal square root of the squared length, not a square root and a division: ||v|| floored at 1e-8.
    # The squared length as three products added, not a reduction over the size-3 axis: XLA:CPU fuses that
    # reduction into the bone product's kernel, where it ran slower than the product itself
    # (benchmarks/results/optimisations.md, "GSPS's prior: limb directions without a size-3 reduction").
    sq = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    v = v * jax.lax.rsqrt(jnp.maximum(sq, 1e-16))[..., None]
    return v.reshape(frames.shape)


# --------------------------------------------------------------------------------------------
# The normalizing-flow pose prior.


def householder_product(u: Float[Array, "n d"]) -> Float[Array, "d d"]:
    """Returns the orthogonal `Q = H_1 H_2 ... H_n` with `H_i = I - 2 u_i u_i^T / (u_i^T u_i)`."""

    def step(q, v):
        return q - 2.0 * (q @ v)[:, None] * v[None, :], None

    # The n directions normalised at once, before the loop: only the rank-one updates are serial.
    q, _ = jax.lax.scan(step, jnp.eye(u.shape[-1], dtype=u.dtype), u / jnp.linalg.norm(u, axis=-1, keepdims=True))
    return q


class LinQR(nn.Module):
    """`f Q R + b` with Q a product of d Householder reflections and R upper triangular, positive diagonal."""

    dim: int

    def setup(self):
        d = self.dim
        bound = 1.0 / d**0.5  # torch's kaiming_uniform(a=sqrt 5) and bias bounds for a d x d weight

        def u_init(key, shape):
            u = 0.5 * jax.random.normal(key, shape)
            return u / jnp.linalg.norm(u, axis=1, keepdims=True)

        self.u = self.param("householder", u_init, (d, d))
        self.r = self.param("r", lambda k, s: jax.random.uniform(k, s, minval=-bound, maxval=bound), (d, d))
        self.b = self.param("bias", lambda k, s: jax.random.uniform(k, s, minval=-bound, maxval=bound), (d,))

    def _qr(self):
        r = jnp.triu(self.r, 1) + jnp.diag(jnp.exp(jnp.diag(self.r)))
        return householder_product(self.u), r

    def __call__(self, f: Float[Array, "... d"]):
        """Returns `(f Q R + b, log|det| = sum diag R)`."""
        q, r = self._qr()
        # Q R formed once (d x d), then one product with the batch, not two.
        return f @ (q @ r) + self.b, jnp.broadcast_to(jnp.sum(jnp.diag(self.r)), f.shape[:-1])

    def inverse(self, y: Float[Array, "... d"]) -> Float[Array, "... d"]:
        """Returns f with `f Q R + b = y`."""
        q, r = self._qr()
        flat = (y - self.b).reshape(-1, self.dim)
        w = jax.scipy.linalg.solve_triangular(r, flat.T, trans="T", lower=False).T  # w R = y - b
        return (w @ q.T).reshape(y.shape)


class PReLU(nn.Module):
    """`max(f, 0) + a min(f, 0)` with one learnable slope `a > 0` (init 0.25)."""

    init: float = 0.25

    def setup(self):
        self.log_a = self.param("log_slope", lambda k, s: jnp.full(s, np.log(self.init), jnp.float32), ())

    def __call__(self, f: Float[Array, "... d"]):
        """Returns `(PReLU(f), log|det| = log a * #(f < 0))`."""
        neg = f < 0
        return jnp.where(neg, jnp.exp(self.log_a) * f, f), self.log_a * jnp.sum(neg, axis=-1)

    def inverse(self, y: Float[Array, "... d"]) -> Float[Array, "... d"]:
        """Returns the input whose PReLU is `y`."""
        return jnp.where(y < 0, y * jnp.exp(-self.log_a), y)


class PosePrior(nn.Module):
    """The GSPS pose prior: `n_layers` LinQR layers with a PReLU between consecutive ones.

    `__call__(d)` returns `(z, log|det dz/dd|)`; `inverse(z)` returns d; `log_prob(d)` the density.
    """

    dim: int
    n_layers: int = 3

    def setup(self):
        layers = []
        for i in range(self.n_layers):
            layers.append(LinQR(self.dim, name=f"linqr_{i}"))
            if i < self.n_layers - 1:
                layers.append(PReLU(name=f"prelu_{i}"))
        self.layers = layers

    def __call__(self, d: Float[Array, "... dim"]):
        logdet = jnp.zeros(d.shape[:-1])
        for layer in self.layers:
            d, ld = layer(d)
            logdet = logdet + ld
        return d, logdet

    def inverse(self, z: Float[Array, "... dim"]) -> Float[Array, "... dim"]:
        """Returns the pose whose flow output is `z`: the layers inverted in reverse order."""
        for layer in reversed(self.layers):
            z = layer.inverse(z)
        return z

    def log_prob(self, d: Float[Array, "... dim"]) -> Float[Array, "..."]:
        """Returns `log N(f(d); 0, I) + log|det df/dd|`."""
        z, logdet = self(d)
        return std_normal_log_prob(z) + logdet


def std_normal_log_prob(z: Float[Array, "... d"]) -> Float[Array, "..."]:
    """Returns `log N(z; 0, I)` summed over the last axis."""
    return -0.5 * jnp.sum(z**2, axis=-1) - 0.5 * z.shape[-1] * np.log(2.0 * np.pi)


def prior_loss(prior: PosePrior, params, frames: Float[Array, "b d"], *, parents: tuple[int, ...]):
    """Returns `(loss, metrics)`: the prior's negative log-likelihood per frame (`train_nf.py`)."""
    z, logdet = prior.apply(params, limb_directions(frames, parents))
    log_pz = std_normal_log_prob(z)
    loss = -jnp.mean(log_pz + logdet)
    return loss, {"log_pz": jnp.mean(log_pz), "logdet": jnp.mean(logdet)}


def prior_nll(prior: PosePrior, params, frames: Float[Array, "... d"], parents: tuple[int, ...]) -> Float[Array, "..."]:
    """Returns the negative log-density `-log p(d)` of every frame's limb directions under a trained prior."""
    return -prior.apply(params, limb_directions(frames, parents), method=PosePrior.log_prob)


# --------------------------------------------------------------------------------------------
# Joint roles and angle limits.

_ROLE_PATTERNS = {
    # role: name patterns in priority order (lower-case, separators removed); side by l/left, r/right.
    "hip": ("upperleg", "upleg", "thigh", "hip"),
    "knee": ("lowerleg", "knee", "kne", "shin", "calf", "leg"),
    "foot": ("foot", "ankle", "ank"),
    "shoulder": ("upperarm", "shoulder", "sho", "arm"),
    "elbow": ("lowerarm", "forearm", "elbow", "elb"),
    "wrist": ("wrist", "wri", "hand"),
}


def _side_and_stem(name: str) -> tuple[str | None, str]:
    """Returns `(side, stem)` of a joint name: `RKnee`, `lkne`, `LowerLeg_L`, `LeftUpLeg` -> ("r", "knee"), ..."""
    raw = name.split(":")[-1]
    clean = lambda s: re.sub(r"[^a-z0-9]", "", s.lower())  # noqa: E731
    m = re.search(r"(left|right)", raw, re.IGNORECASE)
    if m:
        return m.group(1)[0].lower(), clean(raw[: m.start()] + raw[m.end() :])
    m = re.search(r"[_.\- ]([LlRr])$", raw) or re.match(r"^([LlRr])[_.\- ]", raw) or re.match(r"^([LR])[A-Z]", raw)
    if m:
        return m.group(1).lower(), clean(raw[: m.start(1)] + raw[m.end(1) :])
    if raw.islower() and raw[:1] in ("l", "r") and any(raw[1:].startswith(p) for ps in _ROLE_PATTERNS.values() for p in ps):
        return raw[0], clean(raw[1:])
    return None, clean(raw)


def angle_roles(names: tuple[str, ...], parents: tuple[int, ...]) -> dict[str, int]:
    """Returns `{role: joint index}` for root, thorax, head and l_/r_ hip, knee, foot, shoulder, elbow, wrist.

    Roles are found from joint names (`RKnee`, `LowerLeg_L`, `lkne`, `LeftLeg`, ...); the thorax
    is the nearest common ancestor of the two shoulders. Raises a ValueError naming the missing role.
    """
    tagged = [_side_and_stem(n) for n in names]
    roles: dict[str, int] = {"root": 0}
    for role, patterns in _ROLE_PATTERNS.items():
        for side in ("l", "r"):
            found = None
            for p in patterns:
                cands = [i for i, (s, stem) in enumerate(tagged) if i > 0 and s == side and stem == p]
                cands = cands or [i for i, (s, stem) in enumerate(tagged) if i > 0 and s == side and stem.startswith(p)]
                if cands:
                    found = cands[0]
                    break
            if found is None:
                raise ValueError(f"angle_roles: no joint for role {side}_{role} among {names}")
            roles[f"{side}_{role}"] = found

    def ancestors(i):
        out = []
        while i >= 0:
            out.append(i)
            i = parents[i]
        return out

    left = ancestors(roles["l_shoulder"])
    common = [a for a in ancestors(roles["r_shoulder"]) if a in left]
    roles["thorax"] = common[0]
    heads = [i for i, (_, stem) in enumerate(tagged) if stem.startswith("head")]
    if not heads:
        raise ValueError(f"angle_roles: no joint named like 'head' among {names}")
    roles["head"] = heads[0]
    return roles


ANGLE_NAMES = (
    "Spine2Hip_l", "Spine2Hip_r", "Leg2HipPlane_l", "Leg2HipPlane_r", "Shoulder2Hip_l", "Shoulder2Hip_r",
    "Leg2ShoulderPlane_l", "Leg2ShoulderPlane_r", "Shoulder2Shoulder", "ShoulderPlane2HipPlane", "Head2Neck",
    "Shoulder2Neck_l", "Shoulder2Neck_r", "ForeArm2ArmPlane_l", "ForeArm2ArmPlane_r",
    "Foot2LegPlane_l", "Foot2LegPlane_r",
)  # fmt: skip
# Which release family each cosine belongs to: the angle loss averages violations per family.
ANGLE_FAMILIES = tuple(n.rsplit("_", 1)[0] if n[-2:] in ("_l", "_r") else n for n in ANGLE_NAMES)


def _cos(a, b):
    return jnp.sum(a * b, -1) / jnp.maximum(jnp.linalg.norm(a, axis=-1) * jnp.linalg.norm(b, axis=-1), 1e-8)


def angle_cosines(frames: Float[Array, "... d"], roles: dict[str, int]) -> Float[Array, "... a"]:
    """Returns the `len(ANGLE_NAMES)` cosines of a pose (after the release's `h36m_valid_angle_check`).

    Vectors are taken from the root (at the origin) or between joints; a plane is the cross
    product of two vectors, oriented so that the left and right sides mirror each other.
    Leg2HipPlane (the shank against the hip-thigh plane) is the knee's bending direction: a knee
    bent backwards flips its sign.
    """
    p = positions(frames)
    j = lambda r: p[..., roles[r], :]  # noqa: E731
    torso = j("thorax") - j("root")
    cross = jnp.cross
    out = {}
    for s in ("l", "r"):
        hip, knee, foot = j(f"{s}_hip"), j(f"{s}_knee"), j(f"{s}_foot")
        sho, elb, wri = j(f"{s}_shoulder"), j(f"{s}_elbow"), j(f"{s}_wrist")
        out[f"Spine2Hip_{s}"] = _cos(hip - j("root"), torso)
        leg_plane = cross(hip - j("root"), knee - hip) if s == "l" else cross(knee - hip, hip - j("root"))
        out[f"Leg2HipPlane_{s}"] = _cos(leg_plane, foot - knee)
        out[f"Shoulder2Hip_{s}"] = _cos(sho - j("thorax"), hip - j("root"))
        out[f"Shoulder2Neck_{s}"] = _cos(sho - j("thorax"), -torso)
        arm_plane = cross(sho - j("thorax"), elb - sho) if s == "l" else cross(elb - sho, sho - j("thorax"))
        out[f"ForeArm2ArmPlane_{s}"] = _cos(arm_plane, wri - elb)
        other = j("r_hip" if s == "l" else "l_hip")
        foot_plane = cross(hip - other, knee - hip) if s == "l" else cross(knee - hip, hip - other)
        out[f"Foot2LegPlane_{s}"] = _cos(foot_plane, foot - knee)
    sho_plane = cross(j("r_shoulder") - j("root"), j("l_shoulder") - j("root"))
    out["Leg2ShoulderPlane_l"] = _cos(sho_plane, j("l_knee") - j("root"))
    out["Leg2ShoulderPlane_r"] = _cos(sho_plane, j("r_knee") - j("root"))
    out["Shoulder2Shoulder"] = _cos(j("r_shoulder") - j("thorax"), j("l_shoulder") - j("thorax"))
    hip_plane = cross(j("thorax") - j("r_hip"), j("thorax") - j("l_hip"))
    out["ShoulderPlane2HipPlane"] = _cos(hip_plane, cross(j("l_shoulder") - j("root"), j("r_shoulder") - j("root")))
    out["Head2Neck"] = _cos(j("head") - j("thorax"), torso)
    return jnp.stack([out[n] for n in ANGLE_NAMES], axis=-1)


def measure_angle_bounds(
    train_frames: Float[np.ndarray, "n d"], roles: dict[str, int], percentile: float, margin: float = 0.0
) -> Float[np.ndarray, "a 2"]:
    """Returns `(len(ANGLE_NAMES), 2)` bounds `[lo, hi]`: the `percentile` and `100 - percentile` percentiles
    of the cosines over training poses, widened by `margin` on both sides (clipped to [-1, 1]).

    The margin matters where an angle barely moves within a subject (the torso's: on the synthetic
    data the spread of Spine2Hip is +-0.035 in cosine), so that a new subject's proportions are
    not counted as violations.
    """
    cos = np.asarray(angle_cosines(jnp.asarray(train_frames, jnp.float32), roles))
    lo = np.percentile(cos, percentile, axis=0) - margin
    hi = np.percentile(cos, 100.0 - percentile, axis=0) + margin
    return np.clip(np.stack([lo, hi], -1), -1.0, 1.0).astype(np.float32)


def angle_violations(cos: Float[Array, "... a"], bounds: Float[Array, "a 2"]) -> Float[Array, "... a"]:
    """Returns how far each cosine leaves `[lo, hi]` (0 inside); a bound applies only where lo >= -0.98 / hi <= 0.98."""
    lo, hi = bounds[:, 0], bounds[:, 1]
    below = jnp.where(lo >= -0.98, jnp.maximum(lo - cos, 0.0), 0.0)
    above = jnp.where(hi <= 0.98, jnp.maximum(cos - hi, 0.0), 0.0)
    return below + above


def angle_loss(cos: Float[Array, "n a"], bounds: Float[Array, "a 2"]) -> Float[Array, ""]:
    """Returns the release's angle loss: per family, the squared violation averaged over the violating elements, summed.

    The `n` rows are the batch's frames: in the data-parallel train step the sums run over every device's.
    """
    v = angle_violations(cos, bounds)
    fam = np.asarray([sorted(set(ANGLE_FAMILIES)).index(f) for f in ANGLE_FAMILIES])
    n_fam = len(set(ANGLE_FAMILIES))
    sq = jax.ops.segment_sum(batch_sum(jnp.sum(v**2, axis=0)), fam, n_fam)
    count = jax.ops.segment_sum(batch_sum(jnp.sum(v > 0, axis=0).astype(jnp.float32)), fam, n_fam)
    return jnp.sum(sq / jnp.maximum(count, 1.0))


def violation_fraction(frames: Float[Array, "... t d"], roles: dict[str, int], bounds: Float[Array, "a 2"]) -> Float[Array, "..."]:
    """Returns the fraction of frames with at least one cosine outside its bounds."""
    return jnp.mean(jnp.any(angle_violations(angle_cosines(frames, roles), bounds) > 0, axis=-1), axis=-1)


# --------------------------------------------------------------------------------------------
# Body parts.


def _subtree(i: int, parents: tuple[int, ...]) -> list[int]:
    out = [i]
    for j in range(len(parents)):
        if j not in out and any(a == i for a in _ancestors(j, parents)):
            out.append(j)
    return sorted(out)


def _ancestors(j: int, parents: tuple[int, ...]) -> list[int]:
    out = []
    while parents[j] >= 0:
        j = parents[j]
        out.append(j)
    return out


def body_parts(names: tuple[str, ...], parents: tuple[int, ...], split: str) -> tuple[tuple[int, ...], ...]:
    """Returns the parts as node indices of root-dropped frames (joint index - 1), in prediction order.

    "lower_upper": the legs (both hip subtrees), then everything else (the release's Human3.6M
    `parts`). "five": torso (the rest), right leg, left leg, right arm, left arm.
    """
    roles = angle_roles(names, parents)
    legs = {s: _subtree(roles[f"{s}_hip"], parents) for s in ("r", "l")}
    arms = {s: _subtree(roles[f"{s}_shoulder"], parents) for s in ("r", "l")}
    nodes = lambda js: tuple(j - 1 for j in js if j > 0)  # noqa: E731
    lower = sorted(set(legs["r"]) | set(legs["l"]))
    if split == "lower_upper":
        upper = [j for j in range(1, len(parents)) if j not in lower]
        return nodes(lower), nodes(upper)
    if split == "five":
        limbs = set(lower) | set(arms["r"]) | set(arms["l"])
        torso = [j for j in range(1, len(parents)) if j not in limbs]
        return nodes(torso), nodes(legs["r"]), nodes(legs["l"]), nodes(arms["r"]), nodes(arms["l"])
    raise ValueError(f"body_parts: split must be one of {PART_SPLITS}, got {split!r}")


def part_coords(parts: tuple[tuple[int, ...], ...]) -> list[np.ndarray]:
    """Returns each part's coordinate indices into a frame vector (`3 j + {0, 1, 2}`)."""
    return [np.asarray([3 * j + c for j in p for c in range(3)]) for p in parts]


# --------------------------------------------------------------------------------------------
# Generator.


class PartGCN(nn.Module):
    """Returns `GCN([h | z]) + [h | z]`: one part's GCN (release `GCN` with BatchNorm), the noise tiled over nodes."""

    hidden: int = 256
    num_stage: int = 4
    execution: Execution = Execution()  # how it runs (the graph convolutions' precision and layout): nn/execution.py

    @nn.compact
    def __call__(
        self, h: Float[Array, "b j f"], z: Float[Array, "b z"], *, train: bool, repeats: int = 1,
    ) -> Float[Array, "b j f"]:
        """`repeats`: each row stands for that many equal rows of the batch (its BatchNorm's, nn/batchnorm.py)."""
        zj = jnp.broadcast_to(z[:, None, :], h.shape[:2] + z.shape[-1:])
        x = jnp.concatenate([h, zj], axis=-1)
        mm = self.execution.precision
        y = GCLStack(self.hidden, self.num_stage, precision=mm, node_major=self.execution.gcn_node_major, name="gcn")(
            x, train=train, repeats=repeats)
        y = GraphConv(x.shape[-1], precision=mm, name="out")(y) + x
        return y[..., : h.shape[-1]]


class GSPSGenerator(nn.Module):
    """GSPS's generator on DCT node features: parts predicted in sequence, each writing back only its own nodes."""

    parts: tuple[tuple[int, ...], ...]
    hidden: int = 256
    num_stage: int = 4
    execution: Execution = Execution()  # as PartGCN.execution (the flow prior keeps float32 always)

    @nn.compact
    def __call__(
        self, nodes: Float[Array, "g j f"], z: Float[Array, "b p z"], *, train: bool, first_repeats: int = 1,
    ) -> Float[Array, "b j f"]:
        """Returns the `b` samples' node features after every part; `b = g * first_repeats`.

        `first_repeats = r > 1`: the samples come in groups of r consecutive rows that share their
        conditioning and their first part's noise (the training grid's nk2, `training_noise`), `nodes`
        holds one row per group and `z[::r, 0]` is each group's first-part noise. The first part, whose
        input is then the same for the r samples of a group, runs once per group (its BatchNorm counting
        each row r times) and its output is repeated; the later parts run on every sample. The same
        numbers as `first_repeats=1` on the repeated nodes, to float32 rounding (tests/test_gsps.py).
        """
        r = first_repeats
        y = nodes
        for i, part in enumerate(self.parts):
            first = i == 0 and r > 1
            zi = z[::r, i] if first else z[:, i]
            out = PartGCN(self.hidden, self.num_stage, self.execution, name=f"part_{i}")(
                y, zi, train=train, repeats=r if first else 1)
            idx = np.asarray(part)
            y = y.at[:, idx].set(out[:, idx])
            if first:
                y = jnp.repeat(y, r, axis=0)
        return y


def generate(
    gen: GSPSGenerator, variables, x: Float[Array, "b t_his d"], z: Float[Array, "b k p z"], *, t_pred: int, n_pre: int,
    train: bool, first_repeats: int = 1,
):
    """Returns the `(b, K, t_his + t_pred, D)` sequences for noises `z` (and the new BatchNorm statistics when training).

    `first_repeats = r`: the K samples of a window come in groups of r consecutive ones sharing their
    first part's noise (`training_noise`'s nk2), so the first part runs once per group (`GSPSGenerator`).
    """
    b, k = z.shape[:2]
    if k % first_repeats:
        raise ValueError(f"generate: first_repeats={first_repeats} must divide the K = {k} samples")
    nodes = condition_nodes(x, t_pred, n_pre)
    nodes = jnp.repeat(nodes, k // first_repeats, axis=0)
    zz = z.reshape((b * k,) + z.shape[2:])
    if train:
        out, upd = gen.apply(variables, nodes, zz, train=True, first_repeats=first_repeats, mutable=["batch_stats"])
    else:
        out, upd = gen.apply(variables, nodes, zz, train=False, first_repeats=first_repeats), None
    seq = from_nodes(out, x.shape[1] + t_pred).reshape((b, k, x.shape[1] + t_pred, -1))
    return seq, upd


def training_noise(key: jax.Array, b: int, n_parts: int, nk1: int, nk2: int, nz: int) -> Float[Array, "b k p z"]:
    """Returns the release's nk1 x nk2 noise grid `(b, nk1 * nk2, P, nz)`: sample (i, j) has first-part noise i, later-part noises (i, j)."""
    k1, k2 = jax.random.split(key)
    first = batch_rows(lambda n: jax.random.normal(k1, (n, nk1, 1, 1, nz)), b)
    rest = batch_rows(lambda n: jax.random.normal(k2, (n, nk1, nk2, n_parts - 1, nz)), b)
    z = jnp.concatenate([jnp.broadcast_to(first, (b, nk1, nk2, 1, nz)), rest], axis=3)
    return z.reshape(b, nk1 * nk2, n_parts, nz)


def sample_noise(key: jax.Array, b: int, k: int, n_parts: int, nz: int) -> Float[Array, "b k p z"]:
    """Returns i.i.d. N(0, I) noise for every part of every sample (test time, any K)."""
    return batch_rows(lambda n: jax.random.normal(key, (n, k, n_parts, nz)), b)


def part_control_noise(key: jax.Array, b: int, k: int, n_parts: int, nz: int, fixed: tuple[int, ...]) -> Float[Array, "b k p z"]:
    """Returns noise where the parts in `fixed` share one draw across the K samples and the others vary."""
    kf, kv = jax.random.split(key)
    shared = jnp.broadcast_to(batch_rows(lambda n: jax.random.normal(kf, (n, 1, n_parts, nz)), b), (b, k, n_parts, nz))
    free = batch_rows(lambda n: jax.random.normal(kv, (n, k, n_parts, nz)), b)
    mask = np.isin(np.arange(n_parts), np.asarray(fixed, int))[None, None, :, None]
    return jnp.where(mask, shared, free)


def _exp_l1_diversity(y: Float[Array, "... k n"], scale: float) -> Float[Array, ""]:
    """Returns `mean_{i<j} exp(-||y_i - y_j||_1 / scale)` over the K axis, averaged over leading axes."""
    # Only the k (k - 1) / 2 pairs i < j are differenced (not all k^2, then the upper triangle), taken as
    # k - 1 slices, the pairs (i, i + s) for each shift s: a slice's gradient is a pad, where a gather of the
    # pairs had a scatter-add as its gradient (measured in GSPS's generator step).
    k = y.shape[-2]
    total = sum(jnp.sum(jnp.exp(-jnp.sum(jnp.abs(y[..., s:, :] - y[..., : k - s, :]), axis=-1) / scale)) for s in range(1, k))
    return total / (np.prod(y.shape[:-2], dtype=np.float64) * (k * (k - 1) // 2))


def _take_last(x: Float[Array, "... n"], idx: np.ndarray) -> Float[Array, "... m"]:
    """Returns `x[..., idx]` for a fixed index array, as slices of its runs of consecutive indices (a slice's
    gradient is a pad; a gather's is a scatter-add)."""
    runs = np.split(idx, np.flatnonzero(np.diff(idx) != 1) + 1)
    return jnp.concatenate([x[..., int(r[0]) : int(r[-1]) + 1] for r in runs], axis=-1)


def _best_of_errors(
    y_g: Float[Array, "b k t d"], y: Float[Array, "b t d"], mm: Float[Array, "b m t d"], how: str,
) -> tuple[Float[Array, "b k"], Float[Array, "b k m"]]:
    """Returns the squared errors of every sample against the true future and against every pseudo future."""
    if how == "pairwise":
        err = jnp.sum((y_g - y[:, None]) ** 2, axis=(-2, -1))
        return err, jnp.sum((y_g[:, :, None] - mm[:, None]) ** 2, axis=(-2, -1))
    if how != "gram":
        raise ValueError(f"generator_loss: best_of must be 'gram' or 'pairwise', got {how!r}")
    b, k = y_g.shape[:2]
    a = (y_g - y[:, None]).reshape(b, k, -1)
    m = (mm - y[:, None]).reshape(b, mm.shape[1], -1)
    err = jnp.sum(a * a, axis=-1)
    return err, pairwise_sq_distances(a, m, a_sq=err)


def generator_loss(
    gen: GSPSGenerator, variables, prior: PosePrior, prior_params, batch: dict, key: jax.Array, *,
    t_his: int, parents: tuple[int, ...], parts: tuple[tuple[int, ...], ...], roles: dict[str, int],
    angle_bounds: Float[Array, "a 2"], n_pre: int, nz: int, nk1: int, nk2: int,
    lambda_his: float, lambda_limb: float, lambda_div_first: float, lambda_div_rest: float, alpha: float, beta: float,
    lambda_recon: float, lambda_recon_mm: float, lambda_prior: float, prior_stride: int, lambda_angle: float,
    best_of: str = "gram", first_part_once: bool = True,
):
    """Returns `(loss, (metrics, batch_stats))`: GSPS's generator objective (release `train.py: loss_function`).

    `first_part_once` (default): the first part's GCN runs once per first-part noise, nk1 times per
    window, instead of once per sample, nk1 * nk2 times (its input is the same for the nk2 samples
    that share the noise; `GSPSGenerator`'s `first_repeats`). False runs it on every sample, as the
    release does; the same parameters after training to float32 rounding (tests/test_gsps.py).

    `batch`: `window (b, T, D)`, `mm (b, M, t_pred, D)` pseudo ground-truth futures and `mm_mask (b, M)`.
    `best_of`: how the (b, K, M) squared errors of the best-of-K terms are formed: "gram" (default) as
    `|a|^2 + |m|^2 - 2 a.m`, one batched product, both sides taken relative to the true future first
    (norms of the order of the distances, little cancellation); "pairwise" as the release does, by
    differencing every (sample, pseudo future) pair, a (b, K, M, t_pred, D) array. The same values to
    float32 rounding (`tests/test_gsps.py`); benchmarks/results/optimisations.md, "GSPS's best-of-K errors", has the A/B.
    """
    w, mm, mm_mask = batch["window"], batch["mm"], batch["mm_mask"]
    b, t_total, _ = w.shape
    t_pred = t_total - t_his
    x, y = w[:, :t_his], w[:, t_his:]
    k_noise, k_phase = jax.random.split(key)
    z = training_noise(k_noise, b, len(parts), nk1, nk2, nz)
    seq, upd = generate(gen, variables, x, z, t_pred=t_pred, n_pre=n_pre, train=True,
                        first_repeats=nk2 if first_part_once else 1)  # (b, K, T, D)
    y_g = seq[:, :, t_his:]
    # Past reconstruction and limb lengths (of every frame, against the first observed frame).
    loss_his = jnp.mean(jnp.sum((seq[:, :, :t_his] - x[:, None]) ** 2, axis=-1))
    limb_gt = bone_lengths(w[:, 0], parents)[:, None, None]
    loss_limb = jnp.mean(jnp.sum((bone_lengths(seq, parents) - limb_gt) ** 2, axis=-1))
    # Diversity: the first part over its nk1 samples (later-part index 0), the later parts over nk2 per first sample.
    coords = part_coords(parts)
    grid = y_g.reshape(b, nk1, nk2, t_pred, -1)
    first = _take_last(grid[:, :, 0], coords[0]).reshape(b, nk1, -1)
    rest = _take_last(grid, np.concatenate(coords[1:])).reshape(b, nk1, nk2, -1)
    div_first = _exp_l1_diversity(first, alpha)
    div_rest = _exp_l1_diversity(rest, beta)
    # Best of nk1 * nk2 against the truth and against every pseudo ground-truth future.
    err, err_mm = _best_of_errors(y_g, y, mm, best_of)  # (b, K), (b, K, M)
    recon = jnp.mean(jnp.min(err, axis=1))
    best_mm = jnp.min(err_mm, axis=1)
    recon_mm = batch_sum(jnp.sum(best_mm * mm_mask)) / jnp.maximum(batch_sum(jnp.sum(mm_mask)), 1.0)
    # Pose prior on every `prior_stride`-th future frame (random phase), limb directions.
    phase = jax.random.randint(k_phase, (), 0, prior_stride)
    idx = jnp.arange(t_pred // prior_stride) * prior_stride + phase
    sub = jnp.take(y_g, idx, axis=2)
    zp, _ = prior.apply(jax.lax.stop_gradient(prior_params), limb_directions(sub, parents))
    nll = -jnp.mean(std_normal_log_prob(zp))
    # Joint-angle limits on every future frame.
    loss_ang = angle_loss(angle_cosines(y_g.reshape(-1, y_g.shape[-1]), roles), angle_bounds)
    loss = (
        lambda_his * loss_his + lambda_limb * loss_limb + lambda_div_first * div_first + lambda_div_rest * div_rest
        + lambda_recon * recon + lambda_recon_mm * recon_mm + lambda_prior * nll + lambda_angle * loss_ang
    )
    ade = jnp.mean(jnp.min(jnp.mean(jnp.linalg.norm(y_g - y[:, None], axis=-1), axis=-1), axis=1))
    metrics = {
        "his": loss_his, "limb": loss_limb, "div_first": div_first, "div_rest": div_rest, "recon": recon,
        "recon_mm": recon_mm, "prior_nll": nll, "angle": loss_ang, "ade": ade,
    }
    return loss, (metrics, upd["batch_stats"])


# --------------------------------------------------------------------------------------------
# Pseudo multimodal ground truth.


def candidate_pool(train_frames: list[np.ndarray], t_his: int, t_pred: int, stride: int) -> Float[np.ndarray, "n t d"]:
    """Returns the candidate windows: every `stride` frames of every `(T_i, d)` training sequence (release `data_candi`)."""
    t = t_his + t_pred
    out = [f[s : s + t] for f in train_frames for s in range(0, f.shape[0] - t + 1, stride)]
    return np.stack(out).astype(np.float32)


def pseudo_futures(
    windows: Float[np.ndarray, "b t d"], pool: Float[np.ndarray, "n t d"], rng: np.random.Generator, *, t_his: int,
    his_threshold: float, pred_threshold: float, num: int,
) -> tuple[Float[np.ndarray, "b m t_pred d"], Bool[np.ndarray, "b m"]]:
    """Returns `(futures (b, num, t_pred, D), mask (b, num))`: pseudo multimodal ground truth, zero-padded.

    Release conventions (`generate_multimodal_index.py`): a candidate qualifies when its last
    observed pose is within `his_threshold` of the window's (mean per-joint distance) and its
    future is at least `pred_threshold` away from the window's (mean per-joint distance over the
    future); up to `num` are drawn at random. Only the futures enter the loss, so replacing the
    candidates' history by the window's is implicit. The history test is vectorised over the
    batch; the future test runs per window on random chunks of the history-qualified candidates.
    """
    b, t, d = windows.shape
    j, t_pred = d // 3, t - t_his
    last = windows[:, t_his - 1].reshape(b, 1, j, 3)
    dist_his = np.linalg.norm(last - pool[None, :, t_his - 1].reshape(1, -1, j, 3), axis=-1).mean(-1)  # (b, n)
    out = np.zeros((b, num, t_pred, d), np.float32)
    mask = np.zeros((b, num), bool)
    # The release draws `num` of the qualified candidates uniformly without replacement. Taking the
    # first `num` that pass the future test in a random order of the history-qualified ones is the
    # same distribution, and tests only as many futures as it needs: with thousands of
    # history-qualified candidates per window, testing all of them took ~1 s per batch of 16.
    chunk = max(4 * num, 64)
    for i in range(b):
        cand = rng.permutation(np.flatnonzero(dist_his[i] <= his_threshold))
        chosen = []
        for s in range(0, len(cand), chunk):
            c = cand[s : s + chunk]
            dp = np.linalg.norm((pool[c, t_his:] - windows[i, None, t_his:]).reshape(len(c), t_pred, j, 3), axis=-1)
            chosen.extend(c[dp.mean((1, 2)) >= pred_threshold][: num - len(chosen)])
            if len(chosen) == num:
                break
        out[i, : len(chosen)] = pool[chosen, t_his:]
        mask[i, : len(chosen)] = True
    return out, mask
