"""SMPL-X (or SMPL-H) from a user-supplied model `.npz`, evaluated at marker vertices only (MOJO's parameterisation).

    body = load_smplx("SMPLX_NEUTRAL.npz", marker_vertices={"C7": 3832, ...})
    body.markers(body.zero_params())   # (M, 3): linear blend skinning of the M marker vertices

The SMPL-X model files are licensed and not shipped; `load_smplx` reads the official npz keys
(`v_template`, `shapedirs`, `posedirs`, `J_regressor`, `weights`, `kintree_table`,
`hands_componentsl/r`, `hands_meanl/r`). Joints are regressed once from the template and the
shape blend shapes (`J = J_reg v_template + (J_reg S) beta`), so no step of a fit touches the
10,475-vertex mesh. Parameters (`BodyParams`): `transl`, `orient` (6-D global rotation, as MOJO),
`shape` (betas), `pose` (21 body joints, axis-angle, 63), `hand` (PCA coefficients of both hands,
`2 * num_pca_comps`, or 90 axis-angle values when `num_pca_comps=0`); jaw and eyes stay at zero.

An SMPL-H model npz (52 joints: the same pelvis and 21 body joints, then 15 + 15 hand joints, no
jaw or eyes; the body model of AMASS's SMPL-H files) loads the same way (`SmplxBody.num_joints`
says which); MANO's SMPL-H npz has no hand PCA, so load it with `num_pca_comps=0`. An empty
`marker_vertices` gives a joints-only body.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from flax import struct
from jaxtyping import Array, Float

from jaxmotion.body.params import BodyParams, zero_params
from jaxmotion.body.rotation import axis_angle_to_matrix, rot6d_to_matrix
from jaxmotion.body.skeleton import forward_kinematics
from jaxmotion.errors import DataError
from jaxmotion.formats.npz import read_arrays

NUM_JOINTS = 55  # pelvis, 21 body, jaw, 2 eyes, 15 + 15 hand joints
SMPLH_NUM_JOINTS = 52  # pelvis, 21 body, 15 + 15 hand joints
NUM_BODY_JOINTS = 21
REQUIRED_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table")


@struct.dataclass
class SmplxBody:
    """SMPL-X restricted to marker vertices; arrays are pytree leaves, structure is static."""

    v_template: Float[Array, "m 3"]
    shapedirs: Float[Array, "m 3 b"]
    posedirs: Float[Array, "m 3 p"]
    weights: Float[Array, "m j"]
    j_template: Float[Array, "j 3"]
    j_shapedirs: Float[Array, "j 3 b"]
    hand_components: Float[Array, "2 c 45"]
    hand_mean: Float[Array, "2 45"]
    parents: tuple[int, ...] = struct.field(pytree_node=False)
    marker_names: tuple[str, ...] = struct.field(pytree_node=False)
    marker_vertices: tuple[int, ...] = struct.field(pytree_node=False)
    use_pca: bool = struct.field(pytree_node=False, default=True)
    num_joints: int = struct.field(pytree_node=False, default=NUM_JOINTS)  # 55 SMPL-X, 52 SMPL-H

    @property
    def num_betas(self) -> int:
        return self.shapedirs.shape[-1]

    @property
    def num_hand(self) -> int:
        return 2 * self.hand_components.shape[1] if self.use_pca else 90

    def zero_params(self) -> BodyParams:
        """Returns mean shape, zero pose, identity orientation at the origin."""
        return zero_params(self.num_betas, 3 * NUM_BODY_JOINTS, self.num_hand)

    def _rotations(self, params: BodyParams) -> Float[Array, "j 3 3"]:
        if self.use_pca:
            c = self.hand_components.shape[1]
            hands = jnp.stack([params.hand[:c], params.hand[c:]])
            hands = jnp.einsum("sc,scd->sd", hands, self.hand_components) + self.hand_mean
        else:
            hands = params.hand.reshape(2, 45)
        face = jnp.zeros((3 if self.num_joints == NUM_JOINTS else 0, 3), params.pose.dtype)  # SMPL-X jaw, eyes
        aa = jnp.concatenate([params.pose.reshape(-1, 3), face, hands.reshape(-1, 3)])
        return jnp.concatenate([rot6d_to_matrix(params.orient)[None], axis_angle_to_matrix(aa)])

    def _skin(self, params: BodyParams):
        rot = self._rotations(params)
        j_rest = self.j_template + jnp.einsum("jdb,b->jd", self.j_shapedirs, params.shape)
        par = np.asarray(self.parents)
        local_t = jnp.concatenate([j_rest[:1], j_rest[1:] - j_rest[par[1:]]])
        g_r, g_t = forward_kinematics(self.parents, rot, local_t)
        return rot, j_rest, g_r, g_t

    def joints(self, params: BodyParams) -> Float[Array, "j 3"]:
        """Returns the 55 (SMPL-X) or 52 (SMPL-H) posed joints in the model's order, translated."""
        return self._skin(params)[3] + params.transl

    def markers(self, params: BodyParams) -> Float[Array, "m 3"]:
        """Returns marker vertices by linear blend skinning with shape and pose blend shapes."""
        rot, j_rest, g_r, g_t = self._skin(params)
        eye = jnp.eye(3, dtype=rot.dtype)
        pose_feature = (rot[1:] - eye).reshape(-1)
        v = self.v_template + jnp.einsum("mdb,b->md", self.shapedirs, params.shape)
        v = v + jnp.einsum("mdp,p->md", self.posedirs, pose_feature)
        a_t = g_t - jnp.einsum("jik,jk->ji", g_r, j_rest)
        t_r = jnp.einsum("mj,jik->mik", self.weights, g_r)
        t_t = self.weights @ a_t
        return jnp.einsum("mik,mk->mi", t_r, v) + t_t + params.transl


def load_smplx(
    path: str | os.PathLike,
    marker_vertices: dict[str, int],
    *,
    num_betas: int = 10,
    num_pca_comps: int = 12,
    flat_hand_mean: bool = False,
) -> SmplxBody:
    """Returns SMPL-X (55 joints) or SMPL-H (52) from an official model npz, markers at `{name: vertex}` ids.

    `num_pca_comps=0` uses full axis-angle hands (no PCA); `marker_vertices={}` gives joints only.
    Raises FileNotFoundError / ValueError naming the file and the key when the file is missing, a
    key is missing or shapes disagree.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: SMPL-X / SMPL-H model file not found")
    keys = (*REQUIRED_KEYS, "hands_componentsl", "hands_componentsr", "hands_meanl", "hands_meanr")
    data = read_arrays(path, keys, what="SMPL-X / SMPL-H model", required=REQUIRED_KEYS)
    for k, a in data.items():
        kind = np.integer if k == "kintree_table" else np.floating
        if not np.issubdtype(a.dtype, kind):
            raise DataError(path, f"{k} must hold {'integers' if kind is np.integer else 'floating-point numbers'}, got dtype {a.dtype}")
        if not np.isfinite(a).all():
            raise DataError(path, f"{k} holds NaN or inf")
    jreg = data["J_regressor"]
    v_t = np.asarray(data["v_template"], np.float64)
    n_v = v_t.shape[0]
    kin = np.asarray(data["kintree_table"]).astype(np.int64)
    n_j = kin.shape[1] if kin.ndim == 2 else -1
    if n_j not in (NUM_JOINTS, SMPLH_NUM_JOINTS):
        raise ValueError(
            f"{path}: kintree_table has shape {kin.shape}, expected (2, {NUM_JOINTS}) (SMPL-X) or (2, {SMPLH_NUM_JOINTS}) (SMPL-H)"
        )
    checks = {
        "v_template": (v_t.shape, (n_v, 3)),
        "shapedirs": (data["shapedirs"].shape[:2], (n_v, 3)),
        "posedirs": (data["posedirs"].shape, (n_v, 3, 9 * (n_j - 1))),
        "J_regressor": (jreg.shape, (n_j, n_v)),
        "weights": (data["weights"].shape, (n_v, n_j)),
    }
    for key, (got, want) in checks.items():
        if tuple(got) != tuple(want):
            raise ValueError(f"{path}: {key} has shape {tuple(got)}, expected {tuple(want)}")
    if data["shapedirs"].shape[2] < num_betas:
        raise ValueError(f"{path}: shapedirs has {data['shapedirs'].shape[2]} components, num_betas={num_betas}")
    parents = tuple(int(p) if 0 <= p < n_j else -1 for p in kin[0])
    if parents[0] != -1 or any(p >= j for j, p in enumerate(parents) if j > 0):
        raise ValueError(f"{path}: kintree_table is not a tree listed parents-first")
    names = tuple(marker_vertices)
    ids = np.array([marker_vertices[n] for n in names], np.int64)
    if len(ids) and (ids.min() < 0 or ids.max() >= n_v):
        raise ValueError(f"marker_vertices: ids must be in [0, {n_v}) for {path}, got {ids.tolist()}")
    use_pca = num_pca_comps > 0
    if use_pca:
        hk = ("hands_componentsl", "hands_componentsr")
        if any(k not in data for k in hk):
            raise ValueError(f"{path}: num_pca_comps={num_pca_comps} needs keys {list(hk)}; pass num_pca_comps=0")
        comps = np.stack([data[k][:num_pca_comps] for k in hk])
    else:
        comps = np.zeros((2, 0, 45))
    if flat_hand_mean or "hands_meanl" not in data:
        mean = np.zeros((2, 45))
    else:
        mean = np.stack([data["hands_meanl"], data["hands_meanr"]])
    sd = np.asarray(data["shapedirs"][:, :, :num_betas], np.float64)
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    return SmplxBody(
        v_template=f32(v_t[ids]),
        shapedirs=f32(sd[ids]),
        posedirs=f32(np.asarray(data["posedirs"])[ids]),
        weights=f32(np.asarray(data["weights"])[ids]),
        j_template=f32(jreg @ v_t),
        j_shapedirs=f32(np.einsum("jv,vdb->jdb", jreg, sd)),
        hand_components=f32(comps),
        hand_mean=f32(mean),
        parents=parents,
        marker_names=names,
        marker_vertices=tuple(int(i) for i in ids),
        use_pca=use_pca,
        num_joints=n_j,
    )
