"""GSPS (Mao, Liu, Salzmann, ICCV 2021) in PyTorch: the flow pose prior, the part-sequential GCN generator, its loss.

The twin of jaxmotion/models/gsps.py, written from the equations its docstring states:

* Pose prior: a pose is its `J - 1` unit limb directions `d_i = (p_i - p_parent(i)) / ||.||`.
  Layers `f' = PReLU(f Q R + b)` (the last without PReLU), Q = H_1 ... H_d a product of Householder
  reflections `H_i = I - 2 u_i u_i^T / u_i^T u_i`, `R = triu(R, 1) + diag(exp(diag R))`, so
  `log |det| = sum diag R`; PReLU with one slope a = exp(log_slope), `log |det| = log a` per
  negative element. Exact inverse: `f = (y - b) R^-1 Q^T` through PReLU^-1.
* Generator: DCT node features of the padded history (`divsamp.condition_nodes`); one GCN per body
  part (GCL-BN-Tanh in -> hidden, `num_stage` residual pairs, a graph convolution back to the
  input width, plus the input) on `[h | z_part]`; part i writes back only its own nodes, parts in
  sequence; the inverse DCT gives the whole sequence.
* Objective (`generator_loss`): past reconstruction, limb lengths, exp(-L1 / scale) diversity of the
  first part over nk1 and of the later parts over nk2, best-of-K reconstruction against the truth
  and the pseudo ground truth, the prior's `-log N(f(d); 0, I)` on every `prior_stride`-th future
  frame, and the joint-angle limit loss.

Random draws (the noise grid and the prior's frame phase) are arguments, so a parity test can feed
both frameworks the same ones; `training_noise` / `sample_noise` draw them here for the benchmark.
Joint roles (`roles`, name -> joint index) and body parts (node indices) are passed in.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from benchmarks.torch_ref.divsamp import GCLStack, GraphConv, bone_lengths, condition_nodes, from_nodes

# --------------------------------------------------------------------------------------------
# Limb directions and the flow prior.


def positions(frames: torch.Tensor) -> torch.Tensor:
    """Returns `(..., J, 3)` joint positions of root-dropped frame vectors, the root at the origin."""
    pos = frames.reshape(*frames.shape[:-1], -1, 3)
    return torch.cat([torch.zeros_like(pos[..., :1, :]), pos], dim=-2)


def limb_directions(frames: torch.Tensor, parents) -> torch.Tensor:
    """Returns the unit limb directions of every non-root joint, flattened like the frames."""
    pos = positions(frames)
    child = list(range(1, len(parents)))
    v = pos[..., child, :] - pos[..., [parents[c] for c in child], :]
    v = v / torch.linalg.norm(v, dim=-1, keepdim=True).clamp_min(1e-8)
    return v.reshape(frames.shape)


def householder_product(u: torch.Tensor) -> torch.Tensor:
    """Returns `Q = H_1 H_2 ... H_n` for reflection vectors `u (n, d)`."""
    q = torch.eye(u.shape[-1], dtype=u.dtype, device=u.device)
    for v in u:
        v = v / torch.linalg.norm(v)
        q = q - 2.0 * (q @ v)[:, None] * v[None, :]
    return q


class LinQR(nn.Module):
    """`f Q R + b`: Q orthogonal (Householder product), R upper triangular with diagonal exp(diag R)."""

    def __init__(self, dim: int):
        super().__init__()
        bound = 1.0 / math.sqrt(dim)
        u = 0.5 * torch.randn(dim, dim)
        self.householder = nn.Parameter(u / torch.linalg.norm(u, dim=1, keepdim=True))
        self.r = nn.Parameter(torch.empty(dim, dim).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(dim).uniform_(-bound, bound))

    def qr(self):
        r = torch.triu(self.r, 1) + torch.diag(torch.exp(torch.diagonal(self.r)))
        return householder_product(self.householder), r

    def forward(self, f):
        q, r = self.qr()
        return f @ q @ r + self.bias, torch.diagonal(self.r).sum().expand(f.shape[:-1])

    def inverse(self, y):
        q, r = self.qr()
        w = torch.linalg.solve_triangular(r, (y - self.bias).reshape(-1, y.shape[-1]), upper=True, left=False)
        return (w @ q.T).reshape(y.shape)


class PReLU(nn.Module):
    """`max(f, 0) + a min(f, 0)`, one slope `a = exp(log_slope)` (init 0.25)."""

    def __init__(self, init: float = 0.25):
        super().__init__()
        self.log_slope = nn.Parameter(torch.tensor(math.log(init)))

    def forward(self, f):
        neg = f < 0
        return torch.where(neg, torch.exp(self.log_slope) * f, f), self.log_slope * neg.sum(-1)

    def inverse(self, y):
        return torch.where(y < 0, y * torch.exp(-self.log_slope), y)


class PosePrior(nn.Module):
    """`n_layers` LinQR layers with a PReLU between consecutive ones; `forward(d)` returns `(z, log|det dz/dd|)`."""

    def __init__(self, dim: int, n_layers: int = 3):
        super().__init__()
        layers = []
        for i in range(n_layers):
            layers.append(LinQR(dim))
            if i < n_layers - 1:
                layers.append(PReLU())
        self.layers = nn.ModuleList(layers)

    def forward(self, d):
        logdet = torch.zeros(d.shape[:-1], dtype=d.dtype)
        for layer in self.layers:
            d, ld = layer(d)
            logdet = logdet + ld
        return d, logdet

    def inverse(self, z):
        for layer in reversed(self.layers):
            z = layer.inverse(z)
        return z

    def log_prob(self, d):
        z, logdet = self(d)
        return std_normal_log_prob(z) + logdet


def std_normal_log_prob(z):
    """Returns `log N(z; 0, I)` summed over the last axis."""
    return -0.5 * torch.sum(z**2, dim=-1) - 0.5 * z.shape[-1] * math.log(2.0 * math.pi)


def prior_loss(prior: PosePrior, frames, *, parents):
    """Returns `(loss, metrics)`: the mean negative log-likelihood of single frames' limb directions."""
    z, logdet = prior(limb_directions(frames, parents))
    log_pz = std_normal_log_prob(z)
    return -torch.mean(log_pz + logdet), {"log_pz": torch.mean(log_pz), "logdet": torch.mean(logdet)}


# --------------------------------------------------------------------------------------------
# Joint-angle limits.

ANGLE_NAMES = (
    "Spine2Hip_l", "Spine2Hip_r", "Leg2HipPlane_l", "Leg2HipPlane_r", "Shoulder2Hip_l", "Shoulder2Hip_r",
    "Leg2ShoulderPlane_l", "Leg2ShoulderPlane_r", "Shoulder2Shoulder", "ShoulderPlane2HipPlane", "Head2Neck",
    "Shoulder2Neck_l", "Shoulder2Neck_r", "ForeArm2ArmPlane_l", "ForeArm2ArmPlane_r",
    "Foot2LegPlane_l", "Foot2LegPlane_r",
)  # fmt: skip


def _family(name: str) -> str:
    return name[:-2] if name[-2:] in ("_l", "_r") else name


def _cos(a, b):
    return torch.sum(a * b, -1) / (torch.linalg.norm(a, dim=-1) * torch.linalg.norm(b, dim=-1)).clamp_min(1e-8)


def angle_cosines(frames, roles: dict) -> torch.Tensor:
    """Returns the `len(ANGLE_NAMES)` cosines between limb vectors and body planes of every pose."""
    p = positions(frames)
    j = lambda r: p[..., roles[r], :]  # noqa: E731
    cross = lambda a, b: torch.linalg.cross(a, b, dim=-1)  # noqa: E731
    root, thorax = j("root"), j("thorax")
    torso = thorax - root
    out = {}
    for s in ("l", "r"):
        hip, knee, foot = j(f"{s}_hip"), j(f"{s}_knee"), j(f"{s}_foot")
        sho, elb, wri = j(f"{s}_shoulder"), j(f"{s}_elbow"), j(f"{s}_wrist")
        out[f"Spine2Hip_{s}"] = _cos(hip - root, torso)
        # Planes are oriented so that the left and right sides mirror each other.
        leg_plane = cross(hip - root, knee - hip) if s == "l" else cross(knee - hip, hip - root)
        out[f"Leg2HipPlane_{s}"] = _cos(leg_plane, foot - knee)
        out[f"Shoulder2Hip_{s}"] = _cos(sho - thorax, hip - root)
        out[f"Shoulder2Neck_{s}"] = _cos(sho - thorax, -torso)
        arm_plane = cross(sho - thorax, elb - sho) if s == "l" else cross(elb - sho, sho - thorax)
        out[f"ForeArm2ArmPlane_{s}"] = _cos(arm_plane, wri - elb)
        other = j("r_hip" if s == "l" else "l_hip")
        foot_plane = cross(hip - other, knee - hip) if s == "l" else cross(knee - hip, hip - other)
        out[f"Foot2LegPlane_{s}"] = _cos(foot_plane, foot - knee)
    sho_plane = cross(j("r_shoulder") - root, j("l_shoulder") - root)
    out["Leg2ShoulderPlane_l"] = _cos(sho_plane, j("l_knee") - root)
    out["Leg2ShoulderPlane_r"] = _cos(sho_plane, j("r_knee") - root)
    out["Shoulder2Shoulder"] = _cos(j("r_shoulder") - thorax, j("l_shoulder") - thorax)
    hip_plane = cross(thorax - j("r_hip"), thorax - j("l_hip"))
    out["ShoulderPlane2HipPlane"] = _cos(hip_plane, cross(j("l_shoulder") - root, j("r_shoulder") - root))
    out["Head2Neck"] = _cos(j("head") - thorax, torso)
    return torch.stack([out[n] for n in ANGLE_NAMES], dim=-1)


def angle_violations(cos, bounds):
    """Returns how far each cosine leaves `[lo, hi]`; a bound applies only where lo >= -0.98 / hi <= 0.98."""
    lo, hi = bounds[:, 0], bounds[:, 1]
    below = torch.where(lo >= -0.98, (lo - cos).clamp_min(0.0), torch.zeros_like(cos))
    above = torch.where(hi <= 0.98, (cos - hi).clamp_min(0.0), torch.zeros_like(cos))
    return below + above


def angle_loss(cos, bounds):
    """Returns the sum over angle families of the squared violation averaged over the violating elements."""
    v = angle_violations(cos, bounds)
    sq, count = torch.sum(v**2, dim=0), torch.sum(v > 0, dim=0).to(v.dtype)
    total = v.new_zeros(())
    for fam in dict.fromkeys(_family(n) for n in ANGLE_NAMES):
        cols = [i for i, n in enumerate(ANGLE_NAMES) if _family(n) == fam]
        total = total + sq[cols].sum() / count[cols].sum().clamp_min(1.0)
    return total


# --------------------------------------------------------------------------------------------
# Generator.


class PartGCN(nn.Module):
    """Returns `(GCN([h | z]) + [h | z])[..., :F]`: one part's GCN, the part's noise tiled over the nodes."""

    def __init__(self, n_nodes: int, in_features: int, nz: int, hidden: int = 256, num_stage: int = 4):
        super().__init__()
        self.gcn = GCLStack(n_nodes, in_features + nz, hidden, num_stage)
        self.out = GraphConv(n_nodes, hidden, in_features + nz)

    def forward(self, h, z):
        x = torch.cat([h, z[:, None, :].expand(-1, h.shape[1], -1)], dim=-1)
        return (self.out(self.gcn(x)) + x)[..., : h.shape[-1]]


class GSPSGenerator(nn.Module):
    """Parts predicted in sequence on DCT node features `(b, J, 3 n_pre)`; `forward(nodes, z (b, P, nz))`."""

    def __init__(self, n_nodes: int, parts, n_pre: int = 10, nz: int = 64, hidden: int = 256, num_stage: int = 4):
        super().__init__()
        self.n_pre, self.nz = n_pre, nz
        self.part_nodes = [list(p) for p in parts]
        self.parts = nn.ModuleList(PartGCN(n_nodes, 3 * n_pre, nz, hidden, num_stage) for _ in parts)
        masks = torch.zeros(len(parts), n_nodes, 1, dtype=torch.bool)
        for i, p in enumerate(self.part_nodes):
            masks[i, p] = True
        self.register_buffer("masks", masks, persistent=False)

    def forward(self, nodes, z):
        y = nodes
        for i, gcn in enumerate(self.parts):
            y = torch.where(self.masks[i], gcn(y, z[:, i]), y)
        return y


def generate(gen: GSPSGenerator, x, z, *, t_pred: int):
    """Returns the `(b, K, t_his + t_pred, D)` sequences for noise `z (b, K, P, nz)` (one batch of b * K)."""
    b, k = z.shape[:2]
    nodes = condition_nodes(x, t_pred, gen.n_pre).repeat_interleave(k, dim=0)
    out = gen(nodes, z.reshape(b * k, *z.shape[2:]))
    t = x.shape[1] + t_pred
    return from_nodes(out, t).reshape(b, k, t, -1)


def sample_gsps(gen: GSPSGenerator, x, z, *, t_pred: int):
    """Returns the K futures `(b, K, t_pred, D)` for i.i.d. noise `z (b, K, P, nz)` (put `gen` in eval mode)."""
    return generate(gen, x, z, t_pred=t_pred)[:, :, x.shape[1]:]


def training_noise(b: int, n_parts: int, nk1: int, nk2: int, nz: int, generator=None):
    """Returns the `(b, nk1 * nk2, P, nz)` grid: sample (i, j) has first-part noise i and later-part noises (i, j)."""
    first = torch.randn(b, nk1, 1, 1, nz, generator=generator).expand(b, nk1, nk2, 1, nz)
    rest = torch.randn(b, nk1, nk2, n_parts - 1, nz, generator=generator)
    return torch.cat([first, rest], dim=3).reshape(b, nk1 * nk2, n_parts, nz)


def sample_noise(b: int, k: int, n_parts: int, nz: int, generator=None):
    return torch.randn(b, k, n_parts, nz, generator=generator)


def part_coords(parts):
    """Returns each part's coordinate indices into a frame vector (`3 j + {0, 1, 2}`)."""
    return [[3 * j + c for j in p for c in range(3)] for p in parts]


def exp_l1_diversity(y, scale: float):
    """Returns `mean_{i<j} exp(-||y_i - y_j||_1 / scale)` over the K axis of `y (..., K, n)`."""
    k = y.shape[-2]
    flat = y.reshape(-1, k, y.shape[-1])
    d = torch.cdist(flat, flat, p=1.0)
    iu = torch.triu_indices(k, k, 1)
    return torch.mean(torch.exp(-d[:, iu[0], iu[1]] / scale))


def generator_loss(gen: GSPSGenerator, prior: PosePrior, batch: dict, z, phase: int, *, t_his: int, parents, parts,
                   roles: dict, angle_bounds, nk1: int, nk2: int, lambda_his: float, lambda_limb: float,
                   lambda_div_first: float, lambda_div_rest: float, alpha: float, beta: float, lambda_recon: float,
                   lambda_recon_mm: float, lambda_prior: float, prior_stride: int, lambda_angle: float):
    """Returns `(loss, metrics)`: jaxmotion.models.gsps.generator_loss with the noise grid `z (b, nk1 nk2, P, nz)` and the
    prior's frame phase given. `batch`: `window (b, T, D)`, `mm (b, M, t_pred, D)`, `mm_mask (b, M)`."""
    w, mm, mm_mask = batch["window"], batch["mm"], batch["mm_mask"]
    b, t_total, _ = w.shape
    t_pred = t_total - t_his
    x, y = w[:, :t_his], w[:, t_his:]
    seq = generate(gen, x, z, t_pred=t_pred)
    y_g = seq[:, :, t_his:]
    loss_his = torch.mean(torch.sum((seq[:, :, :t_his] - x[:, None]) ** 2, dim=-1))
    limb_gt = bone_lengths(w[:, 0], parents)[:, None, None]
    loss_limb = torch.mean(torch.sum((bone_lengths(seq, parents) - limb_gt) ** 2, dim=-1))
    coords = part_coords(parts)
    grid = y_g.reshape(b, nk1, nk2, t_pred, -1)
    first = grid[:, :, 0][..., coords[0]].reshape(b, nk1, -1)
    rest = grid[..., [c for cs in coords[1:] for c in cs]].reshape(b, nk1, nk2, -1)
    div_first = exp_l1_diversity(first, alpha)
    div_rest = exp_l1_diversity(rest, beta)
    recon = torch.mean(torch.amin(torch.sum((y_g - y[:, None]) ** 2, dim=(-2, -1)), dim=1))
    best_mm = torch.amin(torch.sum((y_g[:, :, None] - mm[:, None]) ** 2, dim=(-2, -1)), dim=1)  # (b, M)
    recon_mm = torch.sum(best_mm * mm_mask) / mm_mask.sum().clamp_min(1.0)
    sub = y_g[:, :, torch.arange(t_pred // prior_stride) * prior_stride + phase]
    zp, _ = prior(limb_directions(sub, parents))
    nll = -torch.mean(std_normal_log_prob(zp))
    loss_ang = angle_loss(angle_cosines(y_g.reshape(-1, y_g.shape[-1]), roles), angle_bounds)
    loss = (lambda_his * loss_his + lambda_limb * loss_limb + lambda_div_first * div_first + lambda_div_rest * div_rest
            + lambda_recon * recon + lambda_recon_mm * recon_mm + lambda_prior * nll + lambda_angle * loss_ang)
    ade = torch.mean(torch.amin(torch.mean(torch.linalg.norm(y_g - y[:, None], dim=-1), dim=-1), dim=1))
    return loss, {"his": loss_his, "limb": loss_limb, "div_first": div_first, "div_rest": div_rest, "recon": recon,
                  "recon_mm": recon_mm, "prior_nll": nll, "angle": loss_ang, "ade": ade}


def loss_weights(**overrides) -> dict:
    """Returns the release's Human3.6M loss weights (`h36m.yml` lambdas, alpha 100, beta 300, prior stride 3)."""
    w = dict(lambda_his=100.0, lambda_limb=500.0, lambda_div_first=8.0, lambda_div_rest=25.0, alpha=100.0, beta=300.0,
             lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01, prior_stride=3, lambda_angle=100.0)
    w.update(overrides)
    return w

