"""The skeleton body model in PyTorch, and MOJO's original fitting (Adam, three stages), for benchmarks.

The same parameterisation and arrays as `jaxmotion.body.skeleton.SkeletonBody` (6-D global
orientation, axis-angle joint rotations relative to the reference pose, log bone scales, rigid
markers), batched over a leading axis. MOJO fits SMPL-X to each predicted frame with Adam (lr 0.008)
in three stages of 10, 30 and 20 iterations: global translation and orientation, then the body pose,
then the hands; the objective is its Eq. (2). Torch appears only in benchmarks/.
"""

from __future__ import annotations

import numpy as np
import torch


def rot6d_to_matrix(x: torch.Tensor) -> torch.Tensor:
    a1, a2 = x[..., :3], x[..., 3:]
    b1 = a1 / torch.sqrt((a1**2).sum(-1, keepdim=True) + 1e-12)
    a2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = a2 / torch.sqrt((a2**2).sum(-1, keepdim=True) + 1e-12)
    return torch.stack([b1, b2, torch.cross(b1, b2, dim=-1)], dim=-1)


def axis_angle_to_matrix(v: torch.Tensor) -> torch.Tensor:
    t2 = (v**2).sum(-1)[..., None, None]
    small = t2 < 1e-8
    t2s = torch.where(small, torch.ones_like(t2), t2)
    t = torch.sqrt(t2s)
    a = torch.where(small, 1.0 - t2 / 6.0, torch.sin(t) / t)
    b = torch.where(small, 0.5 - t2 / 24.0, (1.0 - torch.cos(t)) / t2s)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = torch.zeros_like(x)
    k = torch.stack([torch.stack([o, -z, y], -1), torch.stack([z, o, -x], -1), torch.stack([-y, x, o], -1)], -2)
    return torch.eye(3, dtype=v.dtype) + a * k + b * (k @ k)


class TorchSkeletonBody:
    """Markers `(B, M, 3)` of a batch of skeleton-body parameters (same maths as the JAX body)."""

    def __init__(self, body):
        self.parents = tuple(body.parents)
        self.offsets = torch.tensor(np.asarray(body.offsets), dtype=torch.float32)
        self.ref_rot = torch.tensor(np.asarray(body.ref_rot), dtype=torch.float32)
        self.marker_offsets = torch.tensor(np.asarray(body.marker_offsets), dtype=torch.float32)
        self.marker_joints = torch.tensor(body.marker_joints, dtype=torch.long)
        depth = []
        for p in self.parents:
            depth.append(0 if p < 0 else depth[p] + 1)
        self.levels = [[j for j in range(len(depth)) if depth[j] == d] for d in range(max(depth) + 1)]

    def markers(self, transl, orient, shape, pose):
        b, j = transl.shape[0], len(self.parents)
        pose_r = axis_angle_to_matrix(pose.reshape(b, j - 1, 3))
        root_r = rot6d_to_matrix(orient) @ self.ref_rot[0]
        local_r = torch.cat([root_r[:, None], self.ref_rot[1:] @ pose_r], dim=1)
        local_t = torch.cat([transl[:, None], self.offsets[1:] * torch.exp(shape)[..., None]], dim=1)
        g_r, g_t = [None] * j, [None] * j
        for d, idx in enumerate(self.levels):
            for k in idx:
                p = self.parents[k]
                if p < 0:
                    g_r[k], g_t[k] = local_r[:, k], local_t[:, k]
                else:
                    g_r[k] = g_r[p] @ local_r[:, k]
                    g_t[k] = g_t[p] + (g_r[p] @ local_t[:, k, :, None])[..., 0]
        r, t = torch.stack(g_r, 1), torch.stack(g_t, 1)
        mj = self.marker_joints
        return (r[:, mj] @ self.marker_offsets[..., None])[..., 0] + t[:, mj]


def mojo_adam_fit(body: TorchSkeletonBody, targets, transl, orient, shape, pose, *,
                  iters=(10, 30, 20), lr=0.008, lambda_pose=0.0005):  # fmt: skip
    """Returns fitted `(transl, orient, pose)` for targets `(B, M, 3)`: MOJO's three Adam stages.

    Stage 1 frees translation and orientation, stage 2 adds the body pose, stage 3 adds the hands
    (the skeleton body has none, so it continues on all body parameters). Shape stays fixed.
    """
    transl = transl.clone().requires_grad_(True)
    orient = orient.clone().requires_grad_(True)
    pose = pose.clone().requires_grad_(True)
    groups = ([transl, orient], [transl, orient, pose], [transl, orient, pose])
    for n, free in zip(iters, groups):
        opt = torch.optim.Adam(free, lr=lr)
        for _ in range(n):
            opt.zero_grad()
            m = body.markers(transl, orient, shape, pose)
            loss = ((m - targets) ** 2).sum() + lambda_pose * (pose**2).sum()
            loss.backward()
            opt.step()
    return transl.detach(), orient.detach(), pose.detach()
