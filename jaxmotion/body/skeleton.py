"""A body model from any BVH skeleton: bone lengths as shape, joint rotations as pose, rigid markers.

    body = skeleton_body_from_bvh(read_bvh("01_01.bvh"), marker_set="cmu41")
    params = body.zero_params()            # the BVH's reference frame, at its own place
    markers = body.markers(params)         # (41, 3) metres

Parameters (`BodyParams`): `transl` is the root joint's position; `orient` (6-D) rotates the
root's reference orientation; `shape[j-1]` is the log length scale of bone `parent(j) -> j`;
`pose[3(j-1):3j]` is joint j's axis-angle rotation relative to its reference rotation, so the
zero pose is the reference frame's pose (a standing person), not the BVH rest pose (for
Bandai-Namco-2 that is every bone along one line). No hands: `hand` has size 0.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jaxtyping import Array, Float

from jaxmotion.body.markersets import MARKER_SETS, marker_spec, resolve_roles
from jaxmotion.body.params import BodyParams, zero_params
from jaxmotion.body.rotation import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix, skew
from jaxmotion.formats.bvh import Bvh, euler_matrices, guess_scale, is_ground_node
from jaxmotion.formats.bvh import forward_kinematics as bvh_fk


@functools.lru_cache(maxsize=None)
def _levels(parents: tuple[int, ...]):
    """Returns `(levels, inverse)`: joints grouped by depth, as positions in depth-sorted order."""
    depth = [0] * len(parents)
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"skeleton: joint {j} listed before its parent {p}")
        depth[j] = 0 if p < 0 else depth[p] + 1
    order = sorted(range(len(parents)), key=lambda j: (depth[j], j))
    pos = {j: i for i, j in enumerate(order)}
    levels = []
    for d in range(max(depth) + 1):
        idx = [j for j in order if depth[j] == d]
        levels.append((np.array(idx), np.array([pos.get(parents[j], 0) for j in idx])))
    return tuple(levels), np.array([pos[j] for j in range(len(parents))])


def forward_kinematics(
    parents: tuple[int, ...], local_r: Float[Array, "j 3 3"], local_t: Float[Array, "j 3"]
) -> tuple[Float[Array, "j 3 3"], Float[Array, "j 3"]]:
    """Returns global rotations and positions; joints of one depth are computed together."""
    levels, inverse = _levels(tuple(parents))
    rs, ts = [], []
    for d, (idx, ppos) in enumerate(levels):
        if d == 0:
            rs.append(local_r[idx])
            ts.append(local_t[idx])
            continue
        r_all, t_all = jnp.concatenate(rs), jnp.concatenate(ts)
        rp, tp = r_all[ppos], t_all[ppos]
        rs.append(rp @ local_r[idx])
        ts.append(tp + jnp.einsum("nij,nj->ni", rp, local_t[idx]))
    return jnp.concatenate(rs)[inverse], jnp.concatenate(ts)[inverse]


@struct.dataclass
class SkeletonBody:
    """A skeleton body model: arrays are pytree leaves, names and structure are static."""

    offsets: Float[Array, "j 3"]  # bone vectors in the parent's frame (metres)
    ref_rot: Float[Array, "j 3 3"]  # local rotations of the reference pose
    marker_offsets: Float[Array, "m 3"]  # each marker in its joint's frame (metres)
    names: tuple[str, ...] = struct.field(pytree_node=False)
    parents: tuple[int, ...] = struct.field(pytree_node=False)
    marker_names: tuple[str, ...] = struct.field(pytree_node=False)
    marker_joints: tuple[int, ...] = struct.field(pytree_node=False)

    @property
    def num_joints(self) -> int:
        return len(self.parents)

    @property
    def num_markers(self) -> int:
        return len(self.marker_names)

    def zero_params(self) -> BodyParams:
        """Returns the reference pose: identity orientation, unit bone scales, zero pose."""
        j = self.num_joints
        p = zero_params(j - 1, 3 * (j - 1), 0)
        return p._replace(transl=self.offsets[0])

    def transforms(self, params: BodyParams) -> tuple[Float[Array, "j 3 3"], Float[Array, "j 3"]]:
        """Returns every joint's global rotation and position."""
        pose_r = axis_angle_to_matrix(params.pose.reshape(-1, 3))
        root_r = rot6d_to_matrix(params.orient) @ self.ref_rot[0]
        local_r = jnp.concatenate([root_r[None], self.ref_rot[1:] @ pose_r])
        scale = jnp.exp(params.shape)[:, None]
        local_t = jnp.concatenate([params.transl[None], self.offsets[1:] * scale])
        return forward_kinematics(self.parents, local_r, local_t)

    def joints(self, params: BodyParams) -> Float[Array, "j 3"]:
        """Returns joint positions `(J, 3)`."""
        return self.transforms(params)[1]

    def markers(self, params: BodyParams) -> Float[Array, "m 3"]:
        """Returns marker positions `(M, 3)`: each its joint's rotation times offset plus position.

        Differentiable with an analytic Jacobian (`_markers`' custom JVP): what a Levenberg-Marquardt
        fit spends most of its time on.
        """
        return _markers(self, params)

    def markers_autodiff(self, params: BodyParams) -> Float[Array, "m 3"]:
        """Returns `markers(params)` differentiated by plain autodiff (the reference for tests)."""
        return self.posed(params)[2]

    def posed(self, params: BodyParams):
        """Returns `(rotations (J, 3, 3), joints (J, 3), markers (M, 3))` in the world."""
        r, t = self.transforms(params)
        mj = np.asarray(self.marker_joints)
        return r, t, jnp.einsum("mij,mj->mi", r[mj], self.marker_offsets) + t[mj]


# JAX rebuilds a `flax.struct` pytree through `__init__`, with whatever leaves a transformation
# uses (`SymbolicZero` tangents in `_markers`' custom JVP), so a check of the fields in `__init__`
# is wrong there (jaxtyping issue #277). This opts `__init__` out of the test suite's import hook
# (`jaxtyped` honours `__no_type_check__` at call time); the methods stay checked.
SkeletonBody.__init__.__no_type_check__ = True


@functools.lru_cache(maxsize=None)
def _moved_by(parents: tuple[int, ...], marker_joints: tuple[int, ...]) -> np.ndarray:
    """Returns `(M, J)` 0/1: joint k's rotation (and bone k's length) moves marker m, i.e. k is
    marker m's joint or one of its ancestors."""
    out = np.zeros((len(marker_joints), len(parents)), np.float32)
    for m, j in enumerate(marker_joints):
        while j >= 0:
            out[m, j] = 1.0
            j = parents[j]
    return out


def _right_jacobian(v: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """Returns SO(3)'s right Jacobian `J_r(v)`: `exp([v + dv]_x) = exp([v]_x) exp([J_r(v) dv]_x)` to first order."""
    t2 = jnp.sum(v**2, -1)[..., None, None]
    small = t2 < 1e-6
    t2s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(t2s)
    a = jnp.where(small, 0.5 - t2 / 24.0, (1.0 - jnp.cos(t)) / t2s)
    b = jnp.where(small, 1.0 / 6.0 - t2 / 120.0, (t - jnp.sin(t)) / (t2s * t))
    k = skew(v)
    return jnp.eye(3, dtype=v.dtype) - a * k + b * (k @ k)


@jax.custom_jvp
def _markers(body: SkeletonBody, params: BodyParams) -> Float[Array, "m 3"]:
    return body.markers_autodiff(params)


def _is_zero(t) -> bool:
    return isinstance(t, jax.custom_derivatives.SymbolicZero)


@functools.partial(_markers.defjvp, symbolic_zeros=True)
def _markers_jvp(primals, tangents):
    """Analytic tangent of the markers: a joint's rotation turns every point below it about the
    joint, a bone's length moves them along the bone; `J_r` maps axis-angle changes to rotations."""
    body, params = primals
    dbody, dp = tangents
    r, t, x = body.posed(params)
    mj = np.asarray(body.marker_joints)
    moved = jnp.asarray(_moved_by(body.parents, body.marker_joints))  # (M, J)
    d = x[:, None, :] - t[None, :, :]  # marker relative to each joint (M, J, 3)
    # Jacobian blocks from the primals only (computed once, however many tangents are pushed).
    out = jnp.zeros_like(x)
    if not _is_zero(dp.transl):
        out = out + dp.transl
    if not _is_zero(dp.orient):
        # Root angular velocity vee(dO O^T) = W d_orient; a point moves by omega x (x - root).
        o = rot6d_to_matrix(params.orient)

        def vee(orient):
            w = rot6d_to_matrix(orient) @ o.T
            return 0.5 * jnp.stack([w[2, 1] - w[1, 2], w[0, 2] - w[2, 0], w[1, 0] - w[0, 1]])

        jac_orient = -skew(x - t[0]) @ jax.jacfwd(vee)(params.orient)  # (M, 3, 6)
        out = out + jac_orient @ dp.orient
    if not _is_zero(dp.pose):
        # Joint k's axis-angle change dtheta turns the points below it by G_k J_r(theta_k) dtheta.
        axes = jnp.swapaxes(r[1:] @ _right_jacobian(params.pose.reshape(-1, 3)), -1, -2)  # (J-1, c, 3)
        jac_pose = jnp.cross(axes[None], d[:, 1:, None, :]) * moved[:, 1:, None, None]  # (M, J-1, c, 3)
        out = out + jnp.einsum("mkci,kc->mi", jac_pose, dp.pose.reshape(-1, 3))
    if not _is_zero(dp.shape):
        parents = np.asarray(body.parents[1:])
        bone = t[1:] - t[parents]  # (J-1, 3): scaled offsets in the world
        out = out + jnp.einsum("mk,k,ki->mi", moved[:, 1:], dp.shape, bone)
    if not _is_zero(dbody.marker_offsets):
        out = out + jnp.einsum("mij,mj->mi", r[mj], dbody.marker_offsets)
    if not (_is_zero(dbody.offsets) and _is_zero(dbody.ref_rot)):
        # The skeleton itself: rare (nothing in the library fits it); plain autodiff.
        zero = lambda a: jnp.zeros_like(a) if _is_zero(a) else a  # noqa: E731
        db = body.replace(offsets=zero(dbody.offsets), ref_rot=zero(dbody.ref_rot), marker_offsets=jnp.zeros_like(body.marker_offsets))
        out = out + jax.jvp(lambda b: b.markers_autodiff(params), (body,), (db,))[1]
    return x, out


def body_frame(joints: np.ndarray, roles: dict[str, int]) -> np.ndarray:
    """Returns `(3, 3)` rows forward, left, up of a standing pose (left: right hip -> left hip)."""
    left = joints[roles["l_thigh"]] - joints[roles["r_thigh"]]
    left /= np.linalg.norm(left)
    up = joints[roles["neck"]] - joints[roles["pelvis"]]
    up -= up @ left * left
    up /= np.linalg.norm(up)
    return np.stack([np.cross(left, up), left, up])


def attach_markers(body: SkeletonBody, marker_names: tuple[str, ...] | str) -> SkeletonBody:
    """Returns `body` with markers placed by `MARKER_SPECS` in its reference (zero-parameter) pose.

    `marker_names` is a tuple of names or the name of a set in `MARKER_SETS` (a set given by name
    also applies its `SET_OVERRIDES` attachments). Raises ValueError
    naming the marker and the joint role when the skeleton has no joint for it.
    """
    set_name = marker_names if isinstance(marker_names, str) else None
    if isinstance(marker_names, str):
        if marker_names not in MARKER_SETS:
            raise ValueError(f"unknown marker set {marker_names!r}; known: {sorted(MARKER_SETS)}")
        marker_names = MARKER_SETS[marker_names]
    roles = resolve_roles(body.names)
    for need in ("pelvis", "neck", "l_thigh", "r_thigh"):
        if need not in roles:
            raise ValueError(f"skeleton joints {body.names} have no {need!r} joint (aliases in markersets.ROLE_ALIASES)")
    r, t = jax.device_get(body.transforms(body.zero_params()))
    frame = body_frame(t, roles)
    joints, offsets = [], []
    for name in marker_names:
        s = marker_spec(name, set_name)
        for role in (s.role, s.to):
            if role is not None and role not in roles:
                raise ValueError(f"marker {name!r} needs a {role!r} joint; skeleton joints are {body.names}")
        j = roles[s.role]
        base = t[j] if s.to is None else t[j] + s.along * (t[roles[s.to]] - t[j])
        world = base + np.array([s.fwd, s.lat, s.up]) @ frame
        joints.append(j)
        offsets.append(r[j].T @ (world - t[j]))
    return body.replace(
        marker_offsets=jnp.asarray(np.array(offsets), jnp.float32),
        marker_names=tuple(marker_names),
        marker_joints=tuple(joints),
    )


def bvh_local_rotations(bvh: Bvh, frames=None) -> np.ndarray:
    """Returns `(F, J, 3, 3)` local rotation matrices of every joint from the BVH rotation channels."""
    motion = np.atleast_2d(bvh.motion if frames is None else bvh.motion[frames])
    out = np.empty((motion.shape[0], bvh.num_joints, 3, 3))
    for j, (chans, start) in enumerate(zip(bvh.channels, bvh.channel_starts)):
        cols = [start + k for k, c in enumerate(chans) if c.endswith("rotation")]
        axes = "".join(c[0] for c in chans if c.endswith("rotation"))
        out[:, j] = euler_matrices(motion[:, cols], axes)
    return out


def skeleton_body_from_bvh(
    bvh: Bvh, marker_set: tuple[str, ...] | str = "cmu41", *, ref_frame: int = 0, scale: float | None = None
) -> SkeletonBody:
    """Returns a skeleton body of the BVH's joints, reference pose = frame `ref_frame` (metres).

    `scale` is metres per file unit (None: `formats.bvh.guess_scale`). A ground node root (Bandai's
    `joint_Root`) is dropped and its rotation folded into the new root's.
    """
    if not 0 <= ref_frame < bvh.num_frames:
        raise ValueError(f"{bvh.path}: ref_frame {ref_frame} outside [0, {bvh.num_frames})")
    scale = guess_scale(bvh) if scale is None else scale
    local = bvh_local_rotations(bvh, [ref_frame])[0]
    offsets = bvh.offsets * scale
    names, parents = bvh.names, bvh.parents
    if is_ground_node(bvh):
        local = np.concatenate([(local[0] @ local[1])[None], local[2:]])
        offsets = offsets[1:]
        names = names[1:]
        parents = tuple(-1 if p <= 0 else p - 1 for p in parents[1:])
    body = SkeletonBody(
        offsets=jnp.asarray(offsets, jnp.float32),
        ref_rot=jnp.asarray(local, jnp.float32),
        marker_offsets=jnp.zeros((0, 3), jnp.float32),
        names=tuple(names),
        parents=tuple(parents),
        marker_names=(),
        marker_joints=(),
    )
    return attach_markers(body, marker_set)


def params_from_bvh(body: SkeletonBody, bvh: Bvh, frames=None, *, scale: float | None = None) -> BodyParams:
    """Returns per-frame `BodyParams` (leading axis F) that reproduce the BVH motion on `body`.

    `body` must come from a BVH with the same skeleton (`skeleton_body_from_bvh`); shape is 0.
    """
    scale = guess_scale(bvh) if scale is None else scale
    local = bvh_local_rotations(bvh, frames)
    pos = bvh_fk(bvh, frames) * scale
    if is_ground_node(bvh):
        local = np.concatenate([(local[:, 0] @ local[:, 1])[:, None], local[:, 2:]], axis=1)
        pos = pos[:, 1:]
    if local.shape[1] != body.num_joints:
        raise ValueError(f"{bvh.path}: {local.shape[1]} joints but the body has {body.num_joints}")
    ref = np.asarray(body.ref_rot, np.float64)
    rel = np.einsum("jki,fjkl->fjil", ref, local)  # ref^T @ R
    n = local.shape[0]
    return BodyParams(
        transl=jnp.asarray(pos[:, 0], jnp.float32),
        orient=_bucketed(_rot6d_jit, local[:, 0] @ ref[0].T),
        shape=jnp.zeros((n, body.num_joints - 1), jnp.float32),
        pose=_bucketed(_axis_angle_jit, rel[:, 1:]).reshape(n, -1),
        hand=jnp.zeros((n, 0), jnp.float32),
    )


_rot6d_jit = jax.jit(matrix_to_rot6d)
_axis_angle_jit = jax.jit(matrix_to_axis_angle)


def _bucketed(fn, a: np.ndarray, bucket: int = 512) -> jax.Array:
    """Returns `fn(a)` (float32) computed on `a` padded to a multiple of `bucket` rows: clips of
    every length then share a few compilations instead of one per length."""
    n = a.shape[0]
    pad = -n % bucket
    a = np.concatenate([a, np.repeat(a[-1:], pad, axis=0)]) if pad else a
    return fn(jnp.asarray(a, jnp.float32))[:n]


def toy_skeleton(marker_set: tuple[str, ...] | str = "cmu41") -> SkeletonBody:
    """Returns a 21-joint standing adult skeleton (metres, Y up, facing +Z, arms down) with CMU joint
    names, for tests and examples that must run without data files."""
    spec = [  # name, parent, offset
        ("Hips", None, (0.0, 0.95, 0.0)), ("Spine", "Hips", (0.0, 0.10, 0.0)),
        ("Spine1", "Spine", (0.0, 0.20, 0.0)), ("Neck", "Spine1", (0.0, 0.18, 0.0)),
        ("Head", "Neck", (0.0, 0.10, 0.0)),
    ]  # fmt: skip
    for s, x in (("Left", 1.0), ("Right", -1.0)):
        spec += [
            (f"{s}Shoulder", "Spine1", (0.03 * x, 0.15, 0.0)), (f"{s}Arm", f"{s}Shoulder", (0.15 * x, 0.0, 0.0)),
            (f"{s}ForeArm", f"{s}Arm", (0.0, -0.29, 0.0)), (f"{s}Hand", f"{s}ForeArm", (0.0, -0.26, 0.0)),
            (f"{s}UpLeg", "Hips", (0.09 * x, -0.05, 0.0)), (f"{s}Leg", f"{s}UpLeg", (0.0, -0.42, 0.0)),
            (f"{s}Foot", f"{s}Leg", (0.0, -0.42, 0.0)), (f"{s}ToeBase", f"{s}Foot", (0.0, -0.05, 0.13)),
        ]  # fmt: skip
    names = tuple(n for n, _, _ in spec)
    parents = tuple(-1 if p is None else names.index(p) for _, p, _ in spec)
    order = _levels(parents)  # validates parents-first order
    del order
    body = SkeletonBody(
        offsets=jnp.asarray([o for _, _, o in spec], jnp.float32),
        ref_rot=jnp.broadcast_to(jnp.eye(3, dtype=jnp.float32), (len(names), 3, 3)),
        marker_offsets=jnp.zeros((0, 3), jnp.float32),
        names=names,
        parents=parents,
        marker_names=(),
        marker_joints=(),
    )
    return attach_markers(body, marker_set)
