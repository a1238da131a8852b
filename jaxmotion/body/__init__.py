"""Body models (skeleton from BVH, SMPL-X) as pytrees of parameters, marker fitting, recursive projection.

- `params.BodyParams`: transl, 6-D orient, shape, pose, hand.
- `skeleton.skeleton_body_from_bvh`: bones as shape, joint rotations as pose, markers from `markersets`.
- `smplx.load_smplx`: SMPL-X from a model npz, markers are vertices, only they are skinned.
- `fit.fit_markers`: MOJO Eq. (2) by Levenberg-Marquardt in three stages; `fit.calibrate`.
- `projection.recursive_projection` / `project_k`: decoder step -> fit -> feed back, in one scan.
"""

from jaxmotion.body.fit import FitResult, calibrate, fit_markers, fit_sequence
from jaxmotion.body.params import BodyParams
from jaxmotion.body.projection import init_from_observed, project_k, recursive_projection
from jaxmotion.body.skeleton import SkeletonBody, params_from_bvh, skeleton_body_from_bvh
from jaxmotion.body.smplx import SmplxBody, load_smplx

__all__ = [
    "BodyParams", "FitResult", "SkeletonBody", "SmplxBody", "calibrate", "fit_markers", "fit_sequence",
    "init_from_observed", "load_smplx", "params_from_bvh", "project_k", "recursive_projection",
    "skeleton_body_from_bvh",
]  # fmt: skip
