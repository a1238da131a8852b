"""Marker data for MOJO: Bandai-Namco-2 motion driving the skeleton body, and MOJO's canonical frame.

    clips = bandai_marker_clips("../shared/data/bandai-namco-2")    # markers (T, 41, 3) per clip
    x = canonicalise(window_markers, window_joints, names)           # PROTOCOL sec. 4, per window

Each clip's BVH rotations and root translation are the skeleton body's parameters (shape 0, the
Bandai skeleton, `bandai` = CMU-41 markers), so every frame is a valid body by construction.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from jaxmotion.body.markersets import resolve_roles


class MarkerClip(NamedTuple):
    name: str
    style: str
    content: str
    markers: np.ndarray  # (T, M, 3) metres, the BVH world (Y up)
    joints: np.ndarray  # (T, J, 3)


def canonical_frame(joints0: np.ndarray, names: tuple[str, ...], up_axis: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Returns `(R (3, 3), origin (3,))` of MOJO's canonical frame for a first frame's joints.

    PROTOCOL sec. 4: X from the left hip to the right hip projected to the ground, Z up (the data's
    `up_axis`), Y forward (Z x X), origin at the root (global translation) of the first frame.
    New coordinates are `R @ (p - origin)`.
    """
    roles = resolve_roles(names)
    up = np.zeros(3)
    up[up_axis] = 1.0
    x = joints0[roles["r_thigh"]] - joints0[roles["l_thigh"]]
    x = x - (x @ up) * up
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    return np.stack([x, y, up]), joints0[0].copy()


def canonicalise(markers: np.ndarray, joints: np.ndarray, names: tuple[str, ...], up_axis: int = 1) -> np.ndarray:
    """Returns `markers (T, M, 3)` in the canonical frame of the window's first frame (`joints (T, J, 3)`)."""
    r, o = canonical_frame(joints[0], names, up_axis)
    return (markers - o) @ r.T


def bandai_marker_clips(root: str | os.PathLike, styles: tuple[str, ...] | None = None, marker_set: str = "bandai"):
    """Returns `(body, [MarkerClip])`: every Bandai-Namco-2 clip (of `styles`) as body markers."""
    from jaxmotion.body.skeleton import params_from_bvh, skeleton_body_from_bvh
    from jaxmotion.data.bvh import read_bvh
    from jaxmotion.data.datasets import _BANDAI_NAME, _bandai_clip_dir

    clip_dir = _bandai_clip_dir(Path(root).expanduser(), None)
    files = sorted(p for p in clip_dir.glob("dataset-2_*.bvh") if _BANDAI_NAME.match(p.stem))
    if not files:
        raise ValueError(f"{clip_dir}: no Bandai-Namco-2 clips")
    body = skeleton_body_from_bvh(read_bvh(files[0]), marker_set)
    markers_of = jax.jit(jax.vmap(body.markers))
    joints_of = jax.jit(jax.vmap(body.joints))
    clips = []
    for f in files:
        m = _BANDAI_NAME.match(f.stem)
        if styles is not None and m["style"] not in styles:
            continue
        p = params_from_bvh(body, read_bvh(f))
        clips.append(MarkerClip(f.stem, m["style"], m["content"], np.asarray(markers_of(p)), np.asarray(joints_of(p))))
    return body, clips
