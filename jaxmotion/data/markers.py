"""Marker data for MOJO: Bandai-Namco-2 motion driving the skeleton body, and MOJO's canonical frame.

    ds = load_bandai_markers("../shared/data/bandai-namco-2")       # a MotionDataset of 41 markers
    body, clips = bandai_marker_clips("../shared/data/bandai-namco-2")  # markers (T, 41, 3) per clip
    x = canonicalise(window_markers, window_joints, names)           # protocol §5, per window

Each clip's BVH rotations and root translation are the skeleton body's parameters (shape 0, the
Bandai skeleton, `bandai` = CMU-41 markers), so every frame is a valid body by construction.
The command line reaches the dataset through a config's `data_options={"markers": "bandai"}`
(`datasets.load_dataset`). This is a dataset loader beside `load_bandai` (the same clips, split and
protocol, `bandai.BANDAI_*`); it builds on the body model (`jaxmotion.body`), which sits below
`data/` and never imports it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

from jaxmotion.body.markersets import MARKER_SETS, resolve_roles
from jaxmotion.body.skeleton import params_from_bvh, skeleton_body_from_bvh
from jaxmotion.data.bandai import (
    BANDAI_NAME, BANDAI_PROTOCOL, BANDAI_TEST_STYLES, BANDAI_TRAIN_STYLES, bandai_clip_dir, default_cache_dir,
)  # fmt: skip
from jaxmotion.data.types import MotionDataset, Sequence, Skeleton
from jaxmotion.data.windows import canonicalise_windows
from jaxmotion.formats.atomic import savez_atomic
from jaxmotion.formats.bvh import read_bvh


class MarkerClip(NamedTuple):
    """One clip's virtual markers `(T, M, 3)` and joints `(T, J, 3)` in metres, with its style and content labels."""

    name: str
    style: str
    content: str
    markers: np.ndarray  # (T, M, 3) metres, the BVH world (Y up)
    joints: np.ndarray  # (T, J, 3)


def canonical_frames(joints: np.ndarray, names: tuple[str, ...], up_axis: int = 1) -> np.ndarray:
    """Returns `(T, 4, 3)`: MOJO's canonical frame at every frame of `joints (T, J, 3)`: rows R, then origin o.

    [protocol §5][marker-canonicalisation]: X from the left hip to the right hip projected to the ground, Z up (the data's
    `up_axis`), Y forward (Z x X), origin at the root (global translation). New coordinates of a
    point p are `R @ (p - o)` (`jaxmotion.data.windows.canonicalise_windows`).
    """
    roles = resolve_roles(names)
    up = np.zeros(3)
    up[up_axis] = 1.0
    x = joints[:, roles["r_thigh"]] - joints[:, roles["l_thigh"]]
    x = x - (x @ up)[:, None] * up
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(up, x)
    r = np.stack([x, y, np.broadcast_to(up, x.shape)], axis=1)
    return np.concatenate([r, joints[:, None, 0]], axis=1).astype(np.float32)


def canonicalise(markers: np.ndarray, joints: np.ndarray, names: tuple[str, ...], up_axis: int = 1) -> np.ndarray:
    """Returns `markers (T, M, 3)` in the canonical frame of the window's first frame (`joints (T, J, 3)`)."""
    t, m = markers.shape[:2]
    canon = canonical_frames(joints[:1], names, up_axis)
    return canonicalise_windows(markers.reshape(1, t, 3 * m), canon)[0].reshape(t, m, 3)


def bandai_marker_clips(
    root: str | os.PathLike, styles: tuple[str, ...] | None = None, marker_set: str = "bandai",
    cache_dir: str | os.PathLike | None = None,
):  # fmt: skip
    """Returns `(body, [MarkerClip])`: every Bandai-Namco-2 clip (of `styles`) as body markers
    (`cache_dir`: where the tarball is extracted, as `load_bandai`)."""
    clip_dir = bandai_clip_dir(Path(root).expanduser(), cache_dir)
    files = sorted(p for p in clip_dir.glob("dataset-2_*.bvh") if BANDAI_NAME.match(p.stem))
    if not files:
        raise ValueError(f"{clip_dir}: no Bandai-Namco-2 clips")
    body = skeleton_body_from_bvh(read_bvh(files[0]), marker_set)
    # Fixed-size chunks: one compilation for every clip length.
    chunk = 2048
    points_of = jax.jit(jax.vmap(lambda p: (body.markers(p), body.joints(p))))
    clips = []
    for f in files:
        m = BANDAI_NAME.match(f.stem)
        if styles is not None and m["style"] not in styles:
            continue
        p = params_from_bvh(body, read_bvh(f))
        n = p.transl.shape[0]
        mk, jt = [], []
        for s in range(0, n, chunk):
            c = jax.tree.map(lambda a: a[s : s + chunk], p)
            pad = chunk - c.transl.shape[0]
            c = jax.tree.map(lambda a: np.concatenate([a, np.repeat(a[-1:], pad, 0)]) if pad else a, c)
            a, b = points_of(c)
            mk.append(np.asarray(a)[: chunk - pad])
            jt.append(np.asarray(b)[: chunk - pad])
        clips.append(MarkerClip(f.stem, m["style"], m["content"], np.concatenate(mk), np.concatenate(jt)))
    return body, clips


# The stick figure drawn over CMU-41 markers (marker -> marker it hangs from); `origin` first.
_DRAW_PARENT = {
    "CLAV": "C7", "STRN": "CLAV", "T10": "C7", "RBAK": "T10",
    "LFHD": "RFHD", "RFHD": "RBHD", "RBHD": "LBHD", "LBHD": "C7",
    "RFWT": "STRN", "LFWT": "RFWT", "LBWT": "LFWT", "RBWT": "RFWT",
}  # fmt: skip
for _p in ("L", "R"):
    _DRAW_PARENT.update({
        f"{_p}SHO": "CLAV", f"{_p}UPA": f"{_p}SHO", f"{_p}ELB": f"{_p}UPA", f"{_p}FRM": f"{_p}ELB",
        f"{_p}WRA": f"{_p}FRM", f"{_p}WRB": f"{_p}FRM", f"{_p}FIN": f"{_p}WRA", f"{_p}THI": f"{_p}FWT",
        f"{_p}KNE": f"{_p}THI", f"{_p}SHN": f"{_p}KNE", f"{_p}ANK": f"{_p}SHN", f"{_p}HEE": f"{_p}ANK",
        f"{_p}TOE": f"{_p}ANK", f"{_p}MT5": f"{_p}TOE",
    })  # fmt: skip

_CACHE_VERSION = 1


def marker_skeleton(marker_names: tuple[str, ...]) -> Skeleton:
    """Returns the dataset `Skeleton` of a marker set: `origin`, then the markers (parents draw sticks)."""
    names = ("origin",) + tuple(marker_names)
    index = {n: i for i, n in enumerate(names)}
    return Skeleton(names, (-1,) + tuple(index.get(_DRAW_PARENT.get(n, ""), -1) for n in marker_names))


def load_bandai_markers(root: str | os.PathLike, marker_set: str = "bandai", cache_dir: str | os.PathLike | None = None):
    """Returns Bandai-Namco-2 as a marker `MotionDataset` for MOJO ([protocol §4][datasets] split, [protocol §5][marker-canonicalisation] frames).

    The skeleton body of the Bandai skeleton carries `marker_set` (default `bandai`: CMU-41 with
    limb markers rigid per bone); each clip drives it, so every frame is a valid body. Same split,
    rate and window lengths as `load_bandai` (30 fps, 15 -> 60, train styles active exhausted
    feminine masculine, test normal, MM threshold 0.5). Frames are the global marker positions
    (D = 3 M); windows are expressed in the canonical frame of their first frame (X left hip ->
    right hip on the ground, Z up, Y forward, origin at the root joint). `info["body"]` is the body
    (for recursive projection), `info["point_names"]` the marker names, `info["up_axis"]` 2. The
    markers are computed once and cached as an npz beside the extracted clips.
    """
    if not isinstance(marker_set, str) or marker_set not in MARKER_SETS:  # before a clip is read
        raise ValueError(f"markers={marker_set!r}: unknown marker set; known: {sorted(MARKER_SETS)}")
    styles = BANDAI_TRAIN_STYLES + BANDAI_TEST_STYLES
    cache = Path(cache_dir or default_cache_dir()).expanduser().parent / f"bandai2_markers_{marker_set}_v{_CACHE_VERSION}.npz"
    body = None
    if cache.is_file():
        z = np.load(cache, allow_pickle=False)
        names, styl, content = list(z["names"]), list(z["styles"]), list(z["contents"])
        splits = np.cumsum(z["lengths"])[:-1]
        markers, canon = np.split(z["markers"], splits), np.split(z["canon"], splits)
        clip_dir = bandai_clip_dir(Path(root).expanduser(), cache_dir)
        body = skeleton_body_from_bvh(read_bvh(clip_dir / f"{names[0]}.bvh"), marker_set)
    else:
        body, clips = bandai_marker_clips(root, styles, marker_set, cache_dir)
        if not clips:
            raise ValueError(f"{root}: no Bandai-Namco-2 clip has a protocol style {styles}")
        names, styl, content = [c.name for c in clips], [c.style for c in clips], [c.content for c in clips]
        markers = [c.markers.astype(np.float32) for c in clips]
        canon = [canonical_frames(c.joints, body.names, up_axis=1) for c in clips]
        savez_atomic(
            cache, names=np.array(names), styles=np.array(styl), contents=np.array(content),
            lengths=np.array([len(m) for m in markers]), markers=np.concatenate(markers), canon=np.concatenate(canon),
        )  # fmt: skip
    train, test = [], []
    for n, s, c, mk, cn in zip(names, styl, content, markers, canon):
        seq = Sequence(mk, BANDAI_PROTOCOL["fps"], "unknown", c, name=n, canon=cn)
        (test if s in BANDAI_TEST_STYLES else train).append(seq)
    return MotionDataset(
        name=f"bandai2_markers_{marker_set}",
        skeleton=marker_skeleton(body.marker_names),
        **BANDAI_PROTOCOL,
        train=train,
        test=test,
        info={
            "source": str(root),
            "frames": "global",
            "up_axis": 2,
            "ground": "future_heel_min",
            "point_names": tuple(body.marker_names),
            "marker_set": marker_set,
            "body": body,
            "cache": str(cache),
        },
    )
