"""Joint positions -> BVH joint rotations on a given skeleton: one closed-form rotation per joint.

    bvh = read_bvh("clip.bvh")
    out = fit_bvh(bvh, targets, known, reference_frame=bvh.num_frames - 1)   # targets (F, J, 3) in file units
    write_bvh("future.bvh", out, end_sites=read_end_sites("clip.bvh"))

Why not the Levenberg-Marquardt body fit of `jaxmotion.body.fit`: a BVH joint's global rotation is
fixed by the directions of its child bones and nothing else, so each rotation has a closed form.
For every joint, with `u_c` its children's local offsets and `v_c` the target bone vectors, the
rotation minimising `sum_c || R u_c/|u_c| - v_c/|v_c| ||^2` (Wahba's problem) is Kabsch's SVD
solution for two or more non-collinear children; with one child (or collinear ones) it is the
smallest rotation from the reference pose's bone direction to the target's, so the twist about the
bone, which positions cannot tell, is the reference frame's (the last observed pose). Solved parents
first, this reproduces every bone direction exactly, hence every position exactly whenever the
targets have the skeleton's bone lengths (`tests/test_predict.py` round-trips to 1e-6 of the body
size), with no iterations and no compilation. An LM fit of positions would reach the same optimum
in that case; when a model's bone lengths drift, it would bend the bones to hit positions, while
this keeps the predicted pose's bone directions on the input's bone lengths, as retargeting does.
Only numpy.
"""

from __future__ import annotations

import numpy as np

from jaxmotion.formats.bvh import Bvh, euler_matrices
from jaxmotion.formats.bvh_write import POSITION_AXES as _POSITION_AXES
from jaxmotion.formats.bvh_write import motion_from_transforms


def local_transforms(bvh: Bvh, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """Returns `(local rotations (J, 3, 3), local translations (J, 3))` of one frame (offsets, or position channels)."""
    row = bvh.motion[frame]
    rots, trans = np.empty((bvh.num_joints, 3, 3)), bvh.offsets.astype(np.float64).copy()
    for j, (chans, start) in enumerate(zip(bvh.channels, bvh.channel_starts)):
        ang, axes = [], ""
        for k, c in enumerate(chans):
            if c in _POSITION_AXES:
                trans[j, _POSITION_AXES[c]] = row[start + k]
            else:
                ang.append(row[start + k])
                axes += c[0]
        rots[j] = euler_matrices(np.asarray(ang), axes)
    return rots, trans


def smallest_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Returns `(..., 3, 3)` rotations taking unit vectors `a` to unit vectors `b` about `a x b` (Rodrigues)."""
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    k = np.zeros(a.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    # 1 / (1 + c) blows up for opposite vectors: turn those by 180 degrees about any axis orthogonal to a.
    opposite = c < -1 + 1e-9
    r = np.eye(3) + k + k @ k / np.where(opposite, 1.0, 1.0 + c)[..., None, None]
    if np.any(opposite):
        ao = a[opposite]
        axis = np.cross(ao, np.where(np.abs(ao[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        r[opposite] = 2 * axis[:, :, None] * axis[:, None, :] - np.eye(3)
    return r


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def solve_rotation(start: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Returns `(F, 3, 3)` global rotations R with `R u_c` along `v_c`: Kabsch for >= 2 non-collinear children, else `start` turned least.

    `start` `(F, 3, 3)` is the rotation the reference pose gives (it fixes the twist of a single bone);
    `u` `(C, 3)` child offsets in the joint's frame, `v` `(F, C, 3)` target bone vectors.
    """
    uh, vh = _unit(u), _unit(v)
    one = smallest_rotation(np.einsum("fij,j->fi", start, uh[0]), vh[:, 0]) @ start
    if len(u) == 1:
        return one
    h = np.einsum("ci,fcj->fij", uh, vh)  # sum_c u_c v_c^T
    w_, s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(w_, -1, -2)))
    fix = np.ones(s.shape)
    fix[:, 2] = d
    kabsch = np.swapaxes(vt, -1, -2) @ (fix[:, :, None] * np.swapaxes(w_, -1, -2))
    collinear = s[:, 1] < 1e-6 * np.maximum(s[:, 0], 1e-12)
    return np.where(collinear[:, None, None], one, kabsch)


def fit_bvh(bvh: Bvh, targets: np.ndarray, known: np.ndarray, reference_frame: int = -1, move: np.ndarray | None = None) -> Bvh:
    """Returns a copy of `bvh` whose motion puts its joints on `targets` `(F, J, 3)` (file units) where `known` `(J,)`.

    Joints solved parents first (module docstring): the topmost known joint with position channels is
    moved onto its target (other position channels keep the reference frame's values; `move` (J,) names
    the joints to move instead, e.g. both a ground node and the hips it carries); every known joint's
    rotation points its nearest known descendants along the target bones (`targets[c] - targets[j]`);
    other joints keep the local rotations and translations of `reference_frame` (fingers a model does
    not predict, a ground node above the model's root, CMU's `LHipJoint` between two predicted joints).
    """
    targets = np.asarray(targets, np.float64)
    known = np.asarray(known, bool)
    n, f = bvh.num_joints, targets.shape[0]
    if targets.shape[1:] != (n, 3) or known.shape != (n,):
        raise ValueError(f"fit_bvh: targets must be (F, {n}, 3) and known ({n},), got {targets.shape} and {known.shape}")
    if not np.all(np.isfinite(targets[:, known])):
        raise ValueError("fit_bvh: targets of known joints must be finite")
    ref_r, ref_t = local_transforms(bvh, reference_frame % bvh.num_frames)
    has_pos = [any(c in _POSITION_AXES for c in chans) for chans in bvh.channels]
    # Position channels move a joint onto its target only at the top of the known joints (the model's
    # root; Bandai-Namco-2 puts them on every joint): below it they keep the reference frame's values, so
    # the pose is carried by rotations and the input's bone lengths.
    if move is None:
        movable = [has_pos[j] and known[j] and (bvh.parents[j] < 0 or not known[bvh.parents[j]]) for j in range(n)]
    else:
        movable = [bool(m) and has_pos[j] and known[j] for j, m in enumerate(np.asarray(move, bool))]
    children = [[c for c in range(n) if bvh.parents[c] == j] for j in range(n)]
    g = np.empty((f, n, 3, 3))  # global rotations
    p = np.empty((f, n, 3))  # global positions
    local_r = np.empty((f, n, 3, 3))
    trans = {}
    for j in range(n):
        par = bvh.parents[j]
        gp = np.broadcast_to(np.eye(3), (f, 3, 3)) if par < 0 else g[:, par]
        pp = np.zeros((f, 3)) if par < 0 else p[:, par]
        if movable[j]:
            t = np.einsum("fji,fj->fi", gp, targets[:, j] - pp)
        else:
            t = np.broadcast_to(ref_t[j], (f, 3))
        if has_pos[j]:
            trans[j] = t
        p[:, j] = pp + np.einsum("fij,fj->fi", gp, t)
        start = gp @ ref_r[j]
        # What constrains this rotation: the nearest known descendants (through joints the targets leave out,
        # which keep the reference pose, like CMU's LHipJoint) at a non-zero offset, not moved on their own.
        u, cs = _known_descendants(j, children, known, movable, ref_r, ref_t)
        if known[j] and cs:
            g[:, j] = solve_rotation(start, u, targets[:, cs] - targets[:, j : j + 1])
        else:
            g[:, j] = start
        local_r[:, j] = np.swapaxes(gp, -1, -2) @ g[:, j]
    motion = motion_from_transforms(bvh, local_r, trans)
    return Bvh(bvh.names, bvh.parents, bvh.offsets, bvh.channels, motion, bvh.frame_time, bvh.path)


def _known_descendants(j, children, known, movable, ref_r, ref_t) -> tuple[np.ndarray, list[int]]:
    """Returns `(offsets (C, 3) in joint j's frame, joints)` of j's nearest known descendants under the reference pose.

    A descendant is reached through joints that are not known (they keep the reference frame's local
    rotation, so the offset is fixed in j's frame); movable joints and zero offsets constrain nothing.
    """
    u, cs = [], []
    stack = [(c, np.eye(3), np.zeros(3)) for c in reversed(children[j])]
    while stack:
        c, r, t = stack.pop()
        off = t + r @ ref_t[c]
        if known[c]:
            if not movable[c] and np.linalg.norm(off) > 1e-9:
                u.append(off)
                cs.append(c)
            continue
        stack.extend((d, r @ ref_r[c], off) for d in reversed(children[c]))
    return np.asarray(u).reshape(-1, 3), cs


def bvh_from_positions(
    names: tuple[str, ...], parents: tuple[int, ...], positions: np.ndarray, fps: float, rest_frame: int = 0,
    order: str = "ZXY",
) -> Bvh:
    """Returns a BVH of joint positions `(F, J, 3)` whose skeleton is the pose of `rest_frame` (offsets = its bone vectors).

    The root gets position and rotation channels, every other joint `order` rotations; `fit_bvh`
    recovers the rotations, so the file reproduces `positions` exactly where bone lengths are those
    of `rest_frame` (a rigid skeleton, as the synthetic data's) and each bone's direction otherwise.
    """
    positions = np.asarray(positions, np.float64)
    n = len(names)
    if positions.ndim != 3 or positions.shape[1:] != (n, 3) or len(parents) != n:
        raise ValueError(f"bvh_from_positions: positions must be (F, {n}, 3) for {n} names and parents, got {positions.shape}")
    rest = positions[rest_frame]
    offsets = np.array([rest[j] - rest[p] if p >= 0 else np.zeros(3) for j, p in enumerate(parents)])
    rot = tuple(f"{a}rotation" for a in order.upper())
    channels = tuple(("Xposition", "Yposition", "Zposition", *rot) if p < 0 else rot for p in parents)
    zero = np.zeros((1, sum(len(c) for c in channels)))
    zero[0, :3] = rest[0]
    template = Bvh(tuple(names), tuple(int(p) for p in parents), offsets, channels, zero, 1.0 / fps)
    return fit_bvh(template, positions, np.ones(n, bool), reference_frame=0)
