"""Writing BVH files: the inverse of `formats.bvh` (Euler angles from rotation matrices, the text format).

    bvh = read_bvh("clip.bvh")
    motion = motion_from_transforms(bvh, local_rotations, root_positions)   # (F, C) channel values
    write_bvh("out.bvh", dataclasses.replace(bvh, motion=motion), end_sites=read_end_sites("clip.bvh"))

`read_bvh(write_bvh(...))` gives back the same skeleton and, up to the printed precision (1e-6), the
same forward kinematics: `tests/test_predict.py` checks both. Euler angles are decomposed in each
joint's own channel order, so the written file keeps the input's conventions. Only numpy.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from jaxmotion.errors import DataError
from jaxmotion.formats.atomic import write_text_atomic
from jaxmotion.formats.bvh import _POSITION_AXES, Bvh

POSITION_AXES = _POSITION_AXES  # BVH position channel name -> axis index


def matrix_to_euler(r: np.ndarray, axes: str) -> np.ndarray:
    """Returns `(..., 3)` Euler angles in degrees with `R_a0(e0) @ R_a1(e1) @ R_a2(e2) == r` (`formats.bvh.euler_matrices`).

    `axes` is a permutation of "XYZ" (the BVH rotation channels in file order). For this intrinsic
    order, with `(i, j, k)` the axis indices and `s = +1` for an even permutation, the middle angle is
    `asin(s * r[i, k])`; at gimbal lock (`|r[i, k]| = 1`) the last angle is set to 0.
    """
    axes = axes.upper()
    if sorted(axes) != ["X", "Y", "Z"]:
        raise ValueError(f"matrix_to_euler: axes must be a permutation of XYZ, got {axes!r}")
    i, j, k = ("XYZ".index(a) for a in axes)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # even permutation (XYZ, YZX, ZXY): +1
    r = np.asarray(r, np.float64)
    sin_b = np.clip(s * r[..., i, k], -1.0, 1.0)
    b = np.arcsin(sin_b)
    locked = np.abs(sin_b) > 1.0 - 1e-9
    a = np.arctan2(-s * r[..., j, k], r[..., k, k])
    c = np.arctan2(-s * r[..., i, j], r[..., i, i])
    # Gimbal lock: only a +- c is defined; put it all in the first angle.
    a_locked = np.arctan2(s * r[..., k, j], r[..., j, j])
    a = np.where(locked, a_locked, a)
    c = np.where(locked, 0.0, c)
    return np.rad2deg(np.stack([a, b, c], axis=-1))


def unwrap_degrees(angles: np.ndarray) -> np.ndarray:
    """Returns `(F, ...)` angles with 360-degree jumps between consecutive frames removed (smooth curves in an editor)."""
    return np.rad2deg(np.unwrap(np.deg2rad(angles), axis=0))


def motion_from_transforms(bvh: Bvh, local_r: np.ndarray, positions: dict[int, np.ndarray]) -> np.ndarray:
    """Returns `(F, C)` motion rows for `bvh`'s channels from local rotations `(F, J, 3, 3)` and joint translations.

    `positions[j]` is the `(F, 3)` local translation (file units) of a joint with position channels
    (the root's position); a joint with position channels missing from `positions` keeps its OFFSET.
    Rotation channels get `matrix_to_euler` in the joint's own channel order, unwrapped over time.
    """
    local_r = np.asarray(local_r, np.float64)
    f = local_r.shape[0]
    if local_r.shape[1:] != (bvh.num_joints, 3, 3):
        raise ValueError(f"motion_from_transforms: local_r must be (F, {bvh.num_joints}, 3, 3), got {local_r.shape}")
    motion = np.zeros((f, sum(len(c) for c in bvh.channels)))
    for j, (chans, start) in enumerate(zip(bvh.channels, bvh.channel_starts)):
        rot = [(k, c[0]) for k, c in enumerate(chans) if c not in _POSITION_AXES]
        if rot:
            if len(rot) != 3:
                raise ValueError(f"{bvh.path}: joint {bvh.names[j]!r} has {len(rot)} rotation channels; writing needs 3")
            e = unwrap_degrees(matrix_to_euler(local_r[:, j], "".join(a for _, a in rot)))
            for n, (k, _) in enumerate(rot):
                motion[:, start + k] = e[:, n]
        elif not np.allclose(local_r[:, j], np.eye(3), atol=1e-6):
            raise ValueError(f"{bvh.path}: joint {bvh.names[j]!r} has no rotation channels but is given a rotation")
        t = positions.get(j, np.broadcast_to(bvh.offsets[j], (f, 3)))
        for k, c in enumerate(chans):
            if c in _POSITION_AXES:
                motion[:, start + k] = t[:, _POSITION_AXES[c]]
    return motion


def read_end_sites(path: str | os.PathLike) -> dict[int, np.ndarray]:
    """Returns `{joint index: End Site OFFSET of shape (3,)}` of a BVH file (what `read_bvh` skips), in joint order of `read_bvh`."""
    path = Path(path)
    out: dict[int, np.ndarray] = {}
    stack: list[int | None] = []
    pending: int | None = None
    joint = -1
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    for line in lines:
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "MOTION":
            break
        if key in ("ROOT", "JOINT"):
            joint += 1
            pending = joint
        elif key == "End":
            pending = None
        elif key == "{":
            stack.append(pending)
        elif key == "}":
            stack.pop()
        elif key == "OFFSET" and stack and stack[-1] is None:
            parent = next((s for s in reversed(stack) if s is not None), None)
            if parent is not None:
                out[parent] = np.asarray([float(v) for v in tokens[1:4]])
    return out


def write_bvh(path: str | os.PathLike, bvh: Bvh, end_sites: dict[int, np.ndarray] | None = None, precision: int = 6) -> Path:
    """Writes `bvh` (hierarchy and motion) as a BVH file and returns its path.

    Every joint without children gets an End Site: its `(3,)` offset from `end_sites` (`read_end_sites` of the
    source file) when given, else zero. Joints must be listed parents first, as `read_bvh` returns them.
    """
    path = Path(path)
    n = bvh.num_joints
    if bvh.motion.ndim != 2 or bvh.motion.shape[1] != sum(len(c) for c in bvh.channels):
        raise ValueError(f"write_bvh: motion must be (F, {sum(len(c) for c in bvh.channels)}), got {bvh.motion.shape}")
    if not np.all(np.isfinite(bvh.motion)):
        raise DataError(path, "write_bvh: motion holds NaN or inf")
    children: list[list[int]] = [[] for _ in range(n)]
    for c, p in enumerate(bvh.parents):
        if p >= 0:
            children[p].append(c)
    end_sites = end_sites or {}
    fmt = lambda v: " ".join(f"{x:.{precision}f}" for x in v)  # noqa: E731
    out = ["HIERARCHY"]

    def emit(root: int) -> None:
        # Depth first with an explicit stack (a long chain of joints is no recursion limit); an int opens
        # a joint, a string is a joint's closing lines.
        todo: list[int | str] = [root]
        depth = {root: 0}
        while todo:
            j = todo.pop()
            if isinstance(j, str):
                out.append(j)
                continue
            pad = "\t" * depth[j]
            out.append(f"{pad}{'ROOT' if bvh.parents[j] < 0 else 'JOINT'} {bvh.names[j]}")
            out.append(f"{pad}{{")
            out.append(f"{pad}\tOFFSET {fmt(bvh.offsets[j])}")
            if bvh.channels[j]:
                out.append(f"{pad}\tCHANNELS {len(bvh.channels[j])} {' '.join(bvh.channels[j])}")
            closing = f"{pad}}}"
            if not children[j]:
                closing = f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {fmt(end_sites.get(j, np.zeros(3)))}\n{pad}\t}}\n" + closing
            todo.append(closing)
            for c in reversed(children[j]):
                depth[c] = depth[j] + 1
                todo.append(c)

    for j, p in enumerate(bvh.parents):
        if p >= j:
            raise ValueError(f"write_bvh: joint {j} ({bvh.names[j]!r}) listed before its parent {p}")
    order: list[int] = []
    stack = [0]
    while stack:  # depth first, children in index order: `read_bvh` numbers joints this way
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    if order != list(range(n)):
        raise ValueError("write_bvh: joints must be numbered depth first, as `read_bvh` numbers them")
    emit(0)
    out += ["MOTION", f"Frames: {bvh.num_frames}", f"Frame Time: {bvh.frame_time:.10f}"]
    out += [fmt(row) for row in bvh.motion]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, "\n".join(out) + "\n")
    return path
