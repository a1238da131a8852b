"""A trained run's manifest, `predictor.json`: what predicting from the run folder alone needs.

`write_manifest` writes it when a run starts (`experiment.train`): the config, the skeleton (joint
names, parents, median bone lengths), the frame layout (joints kept, root dropped, root-relative or
canonical global frames, metres, fps, t_his / t_pred), the training data's most common facing and the dataset
it came from.
`jaxmotion.tools.predictor` reads it (`load`, `run_config`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from jaxmotion.config import Config, to_dict
from jaxmotion.data.types import MotionDataset
from jaxmotion.formats.atomic import write_text_atomic

MANIFEST = "predictor.json"
VERSION = 1


def layout(ds: MotionDataset) -> dict:
    """Returns the frame layout of `ds`: what a model's input and output vectors mean."""
    marker = ds.info.get("frames") == "global"
    return {
        "joints": list(ds.skeleton.names),
        "parents": [int(p) for p in ds.skeleton.parents],
        "root": ds.skeleton.names[0],
        "frames": "global" if marker else "root_relative",
        "canonicalisation": "per window at its first frame (protocol §5)" if marker else None,
        "vector": "joints 1..J-1 x (x, y, z), root dropped" if not marker else "markers x (x, y, z), origin dropped",
        "units": "m",
        "fps": float(ds.fps),
        "t_his": int(ds.t_his),
        "t_pred": int(ds.t_pred),
        "dim": int(ds.dim),
        "up_axis": ds.info.get("up_axis"),
        "mm_threshold": float(ds.mm_threshold),
    }


def bone_lengths(ds: MotionDataset) -> list[float] | None:
    """Returns the median length (m) of every bone `parent(j) -> j` over the training frames (None without joints)."""
    if ds.info.get("frames") == "global" or not ds.train:
        return None
    parents = np.asarray(ds.skeleton.parents)
    child = np.nonzero(parents >= 0)[0]
    lengths = [np.linalg.norm(s.positions[::10, child] - s.positions[::10, parents[child]], axis=-1) for s in ds.train]
    med = np.median(np.concatenate(lengths), axis=0)
    out = np.zeros(len(parents))
    out[child] = med
    return [round(float(v), 5) for v in out]


def hip_pair(names, parents) -> tuple[int, int] | None:
    """Returns the `(left, right)` joint indices of the hips (a left/right pair of the root's children, by name), or None."""
    from jaxmotion.data.augment import left_right_pairs

    return next(((a, b) for a, b in left_right_pairs(names) if parents[a] == 0 and parents[b] == 0), None)


def facing_angle(joints: np.ndarray, hips: tuple[int, int], up_axis: int) -> np.ndarray:
    """Returns the facing of `(..., J, 3)` poses in degrees: the angle about the up axis of the left-to-right hip
    vector, measured from the next axis after the up one towards the one after that (y up: from z towards x)."""
    v = joints[..., hips[1], :] - joints[..., hips[0], :]
    return np.degrees(np.arctan2(v[..., (up_axis + 2) % 3], v[..., (up_axis + 1) % 3]))


def facing(ds: MotionDataset) -> dict | None:
    """Returns the training frames' most common facing (`facing_angle`, the peak of a 10-degree histogram) and the hip
    joints it is measured on, or None (marker frames, no training data, no named hips, no up axis)."""
    hips = hip_pair(ds.skeleton.names, ds.skeleton.parents)
    up = ds.info.get("up_axis")
    if ds.info.get("frames") == "global" or not ds.train or hips is None or up is None:
        return None
    angles = np.concatenate([facing_angle(s.positions[::10], hips, up) for s in ds.train])
    counts, edges = np.histogram(angles, bins=36, range=(-180, 180))
    peak = int(np.argmax(counts))
    return {"degrees": round(float(edges[peak] + 5), 1), "left": ds.skeleton.names[hips[0]], "right": ds.skeleton.names[hips[1]]}


def motion_ranges(ds: MotionDataset) -> dict | None:
    """Returns the training frames' 99th percentiles of joint speed (m/s, the mean over joints of a frame) and of a
    joint's distance from the root (m, the largest of a frame), or None (marker frames, no training data)."""
    if ds.info.get("frames") == "global" or not ds.train:
        return None
    speed = np.concatenate([np.linalg.norm(np.diff(s.positions, axis=0), axis=-1).mean(-1) * ds.fps for s in ds.train])
    reach = np.concatenate([np.linalg.norm(s.positions[::10, 1:] - s.positions[::10, :1], axis=-1).max(-1) for s in ds.train])
    return {"speed_p99": round(float(np.percentile(speed, 99)), 4), "reach_p99": round(float(np.percentile(reach, 99)), 4)}


def far_from_training(manifest: dict, window: np.ndarray, fps: float) -> list[str]:
    """Returns what makes `window` (`(T, J, 3)` metres, the model's joints) far from the model's training data: bones
    more than 1.5 x longer or shorter than its median, a mean joint speed above 1.5 x its 99th percentile, a joint
    further from the root than 1.25 x its 99th percentile; empty when nothing is."""
    out = []
    names, parents = manifest["layout"]["joints"], manifest["layout"]["parents"]
    if manifest.get("bone_lengths"):
        want = np.asarray(manifest["bone_lengths"])
        have = np.array([np.linalg.norm(window[-1, j] - window[-1, p]) if p >= 0 else 0.0 for j, p in enumerate(parents)])
        odd = [j for j in range(1, len(names)) if want[j] > 0.02 and not 1 / 1.5 <= have[j] / want[j] <= 1.5]
        if odd:
            out.append("proportions: " + ", ".join(f"{names[j]} {have[j]:.2f} m (training data {want[j]:.2f} m)" for j in odd[:4])
                       + (f" and {len(odd) - 4} more bones" if len(odd) > 4 else ""))
    ranges = manifest.get("motion_ranges")
    if ranges and len(window) > 1:
        speed = float(np.linalg.norm(np.diff(window, axis=0), axis=-1).mean() * fps)
        if speed > 1.5 * ranges["speed_p99"]:
            out.append(f"speed: joints move {speed:.2f} m/s on average (training data: 99% of frames under {ranges['speed_p99']:.2f} m/s)")
        reach = float(np.linalg.norm(window[:, 1:] - window[:, :1], axis=-1).max())
        if reach > 1.25 * ranges["reach_p99"]:
            out.append(f"pose range: a joint {reach:.2f} m from the root (training data: 99% of frames within {ranges['reach_p99']:.2f} m)")
    return out


def write_manifest(cfg: Config, ds: MotionDataset, workdir: str | Path, data: str | None = None) -> Path:
    """Writes `workdir/predictor.json` (module docstring) and returns its path."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    manifest = {
        "version": VERSION,
        "method": cfg.method,
        "dataset": {"name": ds.name, "source": _absolute(data or ds.info.get("source") or cfg.dataset), "options": dict(cfg.data_options)},
        "layout": layout(ds),
        "bone_lengths": bone_lengths(ds),
        "facing": facing(ds),
        "motion_ranges": motion_ranges(ds),
        "config": to_dict(cfg),
    }
    path = workdir / MANIFEST
    return write_text_atomic(path, json.dumps(manifest, indent=1, default=_json_default))


def _absolute(source: str) -> str:
    """Returns a data path made absolute where it exists (so a run's data is found from any folder); other sources unchanged."""
    p = Path(str(source)).expanduser()
    return str(p.resolve()) if p.exists() else str(source)


def _json_default(v):
    if isinstance(v, (np.integer, np.floating)):
        return v.item()
    if isinstance(v, (np.ndarray, tuple)):
        return list(v)
    return str(v)
