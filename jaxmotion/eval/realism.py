"""MOJO's realism metrics ([protocol §3][realism-and-action-metrics]): frequency-spectrum entropy, body and bone deformation, foot skating.

Motion is given as frame vectors `(..., T, D)` with `D = 3 * len(names)`: `names` name the points of
a frame (joints or markers) in order. A metric that needs particular points looks them up by name
and raises a `ValueError` listing the names it is missing, before any computation. Every function
reduces over time (and points) only; callers average over samples and windows.

Matched against the MOJO release (`yz-cnsdqz/MOJO-release`, `experiments/utils/eval_metrics.py`
`compute_ps_entropy` / `compute_bone_deform`, `experiments/eval_bm_deform.py`,
`experiments/eval_bm_skating.py`). One deliberate difference: the release averages `-p log p` over
the frequency bins (its entropy divided by T); the protocol ([protocol §3][realism-and-action-metrics]) asks for the entropy, the sum.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import jax.scipy.special
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.body.markersets import LIMB_MARKER_PAIRS

# Rigid body parts whose marker distances should not change (protocol §3 (docs/pages/protocol.md#realism-and-action-metrics); MOJO Tab. 2).
BODY_PARTS: dict[str, tuple[str, ...]] = {
    "head": ("LFHD", "RFHD", "RBHD", "LBHD"),
    "upper_torso": ("RSHO", "LSHO", "CLAV", "C7"),
    "lower_torso": ("RFWT", "LFWT", "LBWT", "RBWT"),
}

# Heel markers for foot skating, CMU (LHEE/RHEE) or SSM2 (LHEL/RHEL) names.
HEEL_NAMES: tuple[tuple[str, str], ...] = (("LHEE", "RHEE"), ("LHEL", "RHEL"))

# The eight limb bones (upper arm, forearm, thigh, shank on each side) in the joint naming of the
# skeletons this project reads; MOJO's `compute_bone_deform` uses the SMPL ones.
LIMB_BONES: dict[str, tuple[tuple[str, str], ...]] = {
    "smpl": (
        ("left_shoulder", "left_elbow"), ("left_elbow", "left_wrist"),
        ("right_shoulder", "right_elbow"), ("right_elbow", "right_wrist"),
        ("left_hip", "left_knee"), ("left_knee", "left_ankle"),
        ("right_hip", "right_knee"), ("right_knee", "right_ankle"),
    ),
    "bandai": (
        ("UpperArm_L", "LowerArm_L"), ("LowerArm_L", "Hand_L"),
        ("UpperArm_R", "LowerArm_R"), ("LowerArm_R", "Hand_R"),
        ("UpperLeg_L", "LowerLeg_L"), ("LowerLeg_L", "Foot_L"),
        ("UpperLeg_R", "LowerLeg_R"), ("LowerLeg_R", "Foot_R"),
    ),
    "h36m": (
        ("LShoulder", "LElbow"), ("LElbow", "LWrist"), ("RShoulder", "RElbow"), ("RElbow", "RWrist"),
        ("LHip", "LKnee"), ("LKnee", "LFoot"), ("RHip", "RKnee"), ("RKnee", "RFoot"),
    ),
    "cmu": (
        ("LeftArm", "LeftForeArm"), ("LeftForeArm", "LeftHand"),
        ("RightArm", "RightForeArm"), ("RightForeArm", "RightHand"),
        ("LeftUpLeg", "LeftLeg"), ("LeftLeg", "LeftFoot"),
        ("RightUpLeg", "RightLeg"), ("RightLeg", "RightFoot"),
    ),
    # Marker data: two markers on the same limb bone (the `bandai` marker set attaches them so,
    # `jaxmotion.body.markersets.LIMB_MARKER_PAIRS`); their distance is what a bone length is for joints.
    "markers": LIMB_MARKER_PAIRS,
}  # fmt: skip


def points(motion: Float[ArrayLike, "... t d"], names: Sequence[str], fn: str = "points") -> Float[Array, "... t v 3"]:
    """Returns the motion as `(..., T, V, 3)` points, checking `D == 3 * len(names)`."""
    if motion.shape[-1] != 3 * len(names):
        raise ValueError(
            f"{fn}: `motion` has D = {motion.shape[-1]} numbers per frame but `names` lists {len(names)} points "
            f"(expected D = {3 * len(names)})"
        )
    return jnp.reshape(jnp.asarray(motion, jnp.float32), motion.shape[:-1] + (len(names), 3))


def name_indices(names: Sequence[str], required: Sequence[str], fn: str) -> list[int]:
    """Returns the indices of `required` in `names`; raises a ValueError listing any that are missing."""
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in required if n not in index]
    if missing:
        raise ValueError(f"{fn}: `names` lacks {missing} (needs {list(required)})")
    return [index[n] for n in required]


# --------------------------------------------------------------------------------------------
# Frequency-spectrum entropy.


def spectrum_entropy(motion: Float[ArrayLike, "... t d"], eps: float = 1e-6) -> Float[Array, "..."]:
    """Returns the entropy of each dimension's normalised power spectrum over time, averaged over dims.

    Power `|FFT_t|^2 + eps` (two-sided, as the release's `fftn(axes=time)`), normalised over the T
    frequency bins, entropy `-sum p log p`.
    """
    ps = jnp.abs(jnp.fft.fft(jnp.asarray(motion, jnp.float32), axis=-2)) ** 2 + eps
    p = ps / jnp.sum(ps, axis=-2, keepdims=True)
    return jnp.mean(jnp.sum(jax.scipy.special.entr(p), axis=-2), axis=-1)  # entr(0) = 0


def fse(pred: Float[ArrayLike, "... k t d"], gt: Float[ArrayLike, "... t d"], eps: float = 1e-6) -> Float[Array, "..."]:
    """Returns FSE: mean over samples of the predictions' spectrum entropy minus the ground truth's (MOJO Sec. 4.1)."""
    if pred.shape[-2:] != gt.shape[-2:]:
        raise ValueError(f"fse: `pred` frames {tuple(pred.shape[-2:])} and `gt` frames {tuple(gt.shape[-2:])} differ")
    return jnp.mean(spectrum_entropy(pred, eps), axis=-1) - spectrum_entropy(gt, eps)


# --------------------------------------------------------------------------------------------
# Deformation.


def _pair_dists(p: Float[Array, "... t v 3"], pairs: Sequence[tuple[int, int]]) -> Float[Array, "... t n"]:
    i = jnp.asarray([a for a, _ in pairs])
    j = jnp.asarray([b for _, b in pairs])
    return jnp.linalg.norm(p[..., i, :] - p[..., j, :], axis=-1)


def body_deformation(
    motion: Float[ArrayLike, "... t d"], names: Sequence[str], parts: Mapping[str, Sequence[str]] = BODY_PARTS
) -> dict[str, Float[Array, "..."]]:
    """Returns per rigid part P `sum_{i<j in P} std_t ||v_ti - v_tj||` in mm (MOJO Tab. 2 "body deformation").

    `motion` is in metres; `parts` maps a part name to its marker names (default: head, upper and
    lower torso of [protocol §3][realism-and-action-metrics]). Distances between points do not depend on a global
    translation, so root-relative frames give the same values as global ones.
    """
    needed = [n for part in parts.values() for n in part]
    name_indices(names, needed, "body_deformation")
    p = points(motion, names, "body_deformation")
    out = {}
    for part, members in parts.items():
        idx = name_indices(names, members, "body_deformation")
        pairs = [(idx[a], idx[b]) for a in range(len(idx)) for b in range(a + 1, len(idx))]
        out[part] = 1000.0 * jnp.sum(jnp.std(_pair_dists(p, pairs), axis=-2), axis=-1)
    return out


def find_limb_bones(names: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """Returns the eight limb bones in the first naming of `LIMB_BONES` that `names` contains fully."""
    have = set(names)
    missing = {}
    for convention, bones in LIMB_BONES.items():
        need = [n for bone in bones for n in bone]
        lack = sorted({n for n in need if n not in have})
        if not lack:
            return bones
        missing[convention] = lack
    detail = "; ".join(f"{c} naming lacks {m}" for c, m in missing.items())
    raise ValueError(f"bone_deformation: no known limb-bone naming in `names` (pass `bones=`): {detail}")


def bone_deformation(
    motion: Float[ArrayLike, "... t d"], names: Sequence[str], bones: Sequence[tuple[str, str]] | None = None
) -> Float[Array, "..."]:
    """Returns BDF: the std over time of each limb bone's length, summed over the bones, in metres (MOJO Tab. 3).

    `bones` are `(joint, joint)` name pairs; by default the eight limb bones found by
    `find_limb_bones` (upper arms, forearms, thighs, shanks).
    """
    bones = find_limb_bones(names) if bones is None else tuple(bones)
    idx = name_indices(names, [n for bone in bones for n in bone], "bone_deformation")
    pairs = [(idx[2 * b], idx[2 * b + 1]) for b in range(len(bones))]
    p = points(motion, names, "bone_deformation")
    return jnp.sum(jnp.std(_pair_dists(p, pairs), axis=-2), axis=-1)


# --------------------------------------------------------------------------------------------
# Foot skating.


def find_heels(names: Sequence[str]) -> tuple[str, str]:
    """Returns the heel marker names present in `names` (LHEE/RHEE, or LHEL/RHEL)."""
    for pair in HEEL_NAMES:
        if all(n in names for n in pair):
            return pair
    raise ValueError(f"foot_skating_ratio: `names` has no heel markers: needs one of {[list(p) for p in HEEL_NAMES]} (or pass `heels=`)")


def foot_skating_ratio(
    motion: Float[ArrayLike, "... t d"],
    names: Sequence[str],
    *,
    fps: float,
    up_axis: int = 2,
    ground: float | Float[ArrayLike, "..."] = 0.0,
    max_height: float = 0.05,
    min_speed: float = 0.075,
    heels: tuple[str, str] | None = None,
) -> Float[Array, "..."]:
    """Returns the fraction of the T-1 frame steps in which both heels skate (MOJO Tab. 2, [protocol §3][realism-and-action-metrics]).

    A heel skates on the step t-1 -> t when at frame t it is within `max_height` (5 cm) of the
    ground plane (`up_axis` coordinate = `ground`) and its speed parallel to the ground exceeds
    `min_speed` (75 mm/s, the release's 5 mm per frame at 15 fps). Needs global positions.
    """
    if up_axis not in (0, 1, 2):
        raise ValueError(f"foot_skating_ratio: `up_axis` must be 0, 1 or 2, got {up_axis}")
    if fps <= 0:
        raise ValueError(f"foot_skating_ratio: `fps` must be positive, got {fps}")
    heels = find_heels(names) if heels is None else tuple(heels)
    idx = name_indices(names, heels, "foot_skating_ratio")
    h = points(motion, names, "foot_skating_ratio")[..., idx, :]  # (..., T, 2, 3)
    flat = [a for a in range(3) if a != up_axis]
    speed = jnp.linalg.norm(jnp.diff(h[..., flat], axis=-3), axis=-1) * fps  # (..., T-1, 2)
    low = jnp.abs(h[..., 1:, :, up_axis] - ground) < max_height
    skate = jnp.all(low & (speed > min_speed), axis=-1)
    return jnp.mean(skate.astype(jnp.float32), axis=-1)


# --------------------------------------------------------------------------------------------
# Per-window evaluation hook.


def window_realism(pred: Float[ArrayLike, "n k t d"], gt: Float[ArrayLike, "n t d"], ds) -> dict[str, np.ndarray]:
    """Returns the realism metrics that `ds` supports, per window `(n,)`, each averaged over the K samples.

    Point names are `ds.info["point_names"]` when given, else the skeleton's joints without the
    root (the root-relative frame layout). FSE always; `BDF` when limb joints are named;
    `deform_<part>` (mm) when MOJO's part markers are named; `foot_skating` only for global
    frames (`ds.info["frames"] == "global"`, up axis `ds.info["up_axis"]`) with heel markers; the
    ground is `ds.info["ground"]` (default 0), or per window the lowest heel height of the true
    future when that is `"future_heel_min"` (canonicalised marker windows, whose floor is unknown).
    """
    pred = jnp.asarray(pred, jnp.float32)
    names = tuple(ds.info.get("point_names") or ds.skeleton.names[1:])
    out = {"FSE": np.asarray(fse(pred, jnp.asarray(gt, jnp.float32)))}
    try:
        out["BDF"] = np.asarray(jnp.mean(bone_deformation(pred, names), axis=-1))
    except ValueError:
        pass
    for part, members in BODY_PARTS.items():
        try:
            v = body_deformation(pred, names, parts={part: members})[part]
            out[f"deform_{part}"] = np.asarray(jnp.mean(v, axis=-1))
        except ValueError:
            pass
    if ds.info.get("frames") == "global":
        try:
            up = ds.info.get("up_axis", 2)
            ground = ds.info.get("ground", 0.0)
            if ground == "future_heel_min":
                # The floor of a canonicalised window is unknown: take the lowest heel of the true
                # future (in 2 s some foot is always down), so heel contact height is 0 there.
                hi = name_indices(names, find_heels(names), "foot_skating_ratio")
                g = points(jnp.asarray(gt, jnp.float32), names, "foot_skating_ratio")[..., hi, up]
                ground = jnp.min(g, axis=(-2, -1))[:, None, None, None]
            r = foot_skating_ratio(pred, names, fps=ds.fps, up_axis=up, ground=ground)
            out["foot_skating"] = np.asarray(jnp.mean(r, axis=-1))
        except ValueError:
            pass
    return out
