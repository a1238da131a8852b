"""Fabricated humanoid BVH clips in the built-in naming conventions (Bandai-Namco, Mixamo, LAFAN1, SMPL): walking-like motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxmotion.formats.bvh import Bvh
from jaxmotion.formats.bvh_write import write_bvh
from jaxmotion.tools.joint_maps import CONVENTIONS

# (role or extra name, parent, offset in metres: x left, y up, z forward). Extras are joints some conventions add.
_BODY = [
    ("pelvis", None, (0, 0, 0)),
    ("spine", "pelvis", (0, 0.10, 0)),
    ("spine_mid", "spine", (0, 0.12, 0)),
    ("chest", "spine_mid", (0, 0.12, 0)),
    ("neck", "chest", (0, 0.20, 0)),
    ("head", "neck", (0, 0.10, 0.02)),
    *[j for s, x in (("l", 1), ("r", -1)) for j in [
        (f"{s}_clavicle", "chest", (0.04 * x, 0.16, 0)),
        (f"{s}_upperarm", f"{s}_clavicle", (0.14 * x, 0, 0)),
        (f"{s}_forearm", f"{s}_upperarm", (0.28 * x, 0, 0)),
        (f"{s}_hand", f"{s}_forearm", (0.25 * x, 0, 0)),
        (f"{s}_finger", f"{s}_hand", (0.08 * x, 0, 0)),
    ]],
    *[j for s, x in (("l", 1), ("r", -1)) for j in [
        (f"{s}_thigh", "pelvis", (0.09 * x, -0.05, 0)),
        (f"{s}_shin", f"{s}_thigh", (0, -0.42, 0)),
        (f"{s}_foot", f"{s}_shin", (0, -0.40, 0)),
        (f"{s}_toe", f"{s}_foot", (0, -0.06, 0.12)),
    ]],
]  # fmt: skip
# The extra joints each convention has: Mixamo and LAFAN1 have Spine1 between Spine and Spine2, Mixamo has fingers.
_EXTRAS = {
    "bandai": {},
    "mixamo": {"spine_mid": "Spine1", "l_finger": "LeftHandIndex1", "r_finger": "RightHandIndex1"},
    "lafan1": {"spine_mid": "Spine1"},
    "smpl22": {"spine_mid": "spine2"},
}


def humanoid_bvh(
    convention: str, path: str | Path, *, frames: int = 150, fps: float = 30.0, unit: float = 0.01, prefix: str = "",
    seed: int = 0, reparent: dict[str, str] | None = None, rename: dict[str, str] | None = None,
) -> Path:
    """Writes a walking humanoid in `convention`'s joint names (`unit` metres per file unit) and returns its path.

    `reparent` {joint name: new parent name} changes the hierarchy (the same names, another tree);
    `rename` renames joints after that; `prefix` goes before every name (Mixamo's `mixamorig:`).
    """
    names_of = {**CONVENTIONS[convention], **_EXTRAS[convention]}
    # A joint whose parent this convention lacks hangs from its grandparent (Bandai's chest from its spine).
    role_parent = {r: p for r, p, _ in _BODY}
    body = []
    for r, p, o in _BODY:
        if r not in names_of:
            continue
        while p is not None and p not in names_of:
            p = role_parent[p]
        body.append((names_of[r], names_of[p] if p else None, o))
    if reparent:
        body = [(n, reparent.get(n, p), o) for n, p, o in body]
    order = _depth_first(body)
    index = {body[i][0]: k for k, i in enumerate(order)}
    names = tuple(body[i][0] for i in order)
    parents = tuple(-1 if body[i][1] is None else index[body[i][1]] for i in order)
    offsets = np.array([body[i][2] for i in order], np.float64) / unit
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    rot = tuple(f"{a}rotation" for a in "ZXY")
    channels = tuple(("Xposition", "Yposition", "Zposition", *rot) if p < 0 else rot for p in parents)
    cols = []
    for j, n in enumerate(names):
        amp = rng.uniform(5, 25, 3) * (2.0 if any(k in n.lower() for k in ("leg", "knee", "hip", "thigh", "shin")) else 1.0)
        phase = rng.uniform(0, 2 * np.pi, 3)
        angles = amp * np.sin(2 * np.pi * 1.0 * t[:, None] + phase)
        if parents[j] < 0:
            pos = np.stack([0.02 * np.sin(2 * np.pi * t), 0.95 + 0.02 * np.sin(4 * np.pi * t), 1.2 * t], axis=1) / unit
            cols.append(pos)
            angles = angles * 0.3
        cols.append(angles)
    motion = np.concatenate(cols, axis=1)
    names = tuple(prefix + (rename or {}).get(n, n) for n in names)
    return write_bvh(path, Bvh(names, parents, offsets, channels, motion, 1.0 / fps))


def _depth_first(body) -> list[int]:
    children: dict[str | None, list[int]] = {}
    for i, (_, p, _) in enumerate(body):
        children.setdefault(p, []).append(i)
    order, stack = [], list(reversed(children[None]))
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children.get(body[i][0], [])))
    return order
