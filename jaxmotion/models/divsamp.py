"""DivSamp (Dang, Nie, Long, Zhang, Li, ACM MM 2022): Gumbel-Softmax sampling from a learned auxiliary space.

Two networks, trained one after the other:

* A GCN CVAE on DCT coefficients (supp. Table 4; `CVAE` in the authors' release
  github.com/Droliven/diverse_sampling, `h36m/nets/cvae.py`). The history is padded to
  `t_his + t_pred` frames by repeating the last observed pose and the first `n_dct = 10` DCT
  coefficients of every coordinate are kept, so a window is a graph of J joints with
  `3 * n_dct` features. Encoder: 9 GCL-BN-Tanh layers (1 + 4 residual pairs, F = 256) on the
  concatenated coefficients of the padded history X and the whole window (X, Y), then two
  linear heads to `mu`, `logvar` (nz = 64). Decoder: z repeated over joints and concatenated with
  the coefficients of X, 9 GCL-BN-Tanh layers, a final graph convolution back to `3 * n_dct`
  features, plus the coefficients of X (a residual on the padded history), then the inverse DCT.
* The sampler (supp. Table 3, Alg. 1-2; `DiverseSampling` in `h36m/nets/diverse_sampling.py`):
  N_beta = GCN on the coefficients of X (5 GCL-BN-Tanh layers, F = 256) + Linear-BN-Tanh to a
  base matrix B (M = 40 vectors of n_b = 128); a coefficient matrix W (K x M) whose rows are
  Gumbel-Softmax samples (`jaxmotion.gumbel`); points `P = W B`; N_gamma = two MLPs
  (Linear-BN-Tanh-Linear, n_h = 64) from each point to the mean `b_k` and log-variance of a
  Gaussian; `z_k = A_k eps + b_k` with `A_k = exp(logvar_k / 2)` and one `eps ~ N(0, I)` per
  window shared by its K latents (as the release's `repeat_interleave(eps, nk)`); every z_k is
  decoded by the frozen CVAE decoder, in BatchNorm evaluation mode. K is a call argument.

Losses: the CVAE's as in the release's `run_cvae.py` (`cvae_loss`); the sampler's Eq. (13)-(15)
(`sampler_loss`): hinge diversity, min-of-K accuracy and the KL of every N(b_k, A_k^2) to N(0, I).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import flax.linen as nn
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from jaxmotion.dct import condition_nodes, from_nodes, to_nodes
from jaxmotion.nn.batch import batch_rows
from jaxmotion.gumbel import COEFFICIENT_KINDS, sample_coefficients
from jaxmotion.losses import dlow_diversity, hinge_diversity, kld_normal
from jaxmotion.models import gsps  # GSPS's joint-angle definitions and loss, for the release's CVAE angle term
from jaxmotion.body.bones import bone_lengths, bone_matrix, bone_vectors  # noqa: F401 (public here too)
from jaxmotion.nn.gaussian import reparameterise
from jaxmotion.nn.gcn import GCLStack, GraphConv
from jaxmotion.nn.batchnorm import BatchNorm
from jaxmotion.nn.execution import Execution
from jaxmotion.nn.linear import Dense

PI_KINDS = ("uniform", "learned_shared", "learned_per_sample")
DIVERSITY_KINDS = ("hinge", "exp")


@dataclasses.dataclass(slots=True)
class DivSampConfig:
    """DivSamp's architecture and both training stages (`Config.method_config` of method "divsamp").

    Defaults are the authors' Human3.6M release (`h36m/configs/config_cvae.py`,
    `config_diverse_sampling.py`) except the step counts and batch sizes, which the configs
    under experiments/configs set per dataset.
    """

    # CVAE (supp. Table 4).
    n_dct: int = 10
    hidden: int = 256
    nz: int = 64
    cvae_residual: int = 4  # 1 + 2 * 4 = 9 GCL-BN-Tanh layers in the encoder and in the decoder
    # CVAE training (release: lr 1e-3, batch 64, 2000 epochs of which 100 at constant lr, grad-norm clip 100).
    cvae_lr: float = 1e-3
    cvae_batch_size: int = 64
    cvae_num_steps: int = 2000
    cvae_lr_fix_fraction: float = 0.05
    cvae_grad_clip: float = 100.0
    beta: float = 0.5  # KL weight (HumanEva-I: 0.05)
    lambda_v: float = 1000.0  # last observed pose vs first predicted frame
    # The release writes `recoverhis + t1_recoverhis_weight` (a typo for `*`): the history
    # reconstruction term enters with weight 1, which we keep.
    lambda_his: float = 1.0
    lambda_limb: float = 1000.0  # bone lengths of every frame vs those of the first observed frame
    # The release's joint-angle term (`t1_angle_weight` 100, `loss_valid_angle_t1` on the predicted future):
    # GSPS's angle loss (`jaxmotion.models.gsps.angle_loss`) under bounds measured on the training poses
    # (GSPS's `measure_angle_bounds`, its percentile / margin / frame-count defaults), a computed
    # `angle_bounds` stage before the CVAE. 0 (default): no angle term, no extra stage.
    cvae_lambda_angle: float = 0.0
    angle_percentile: float = 0.1
    angle_margin: float = 0.05
    angle_bounds_frames: int = 20000
    # The release trains the CVAE on an expanded set (`..._ExpandDataset_T1`): a training window that has
    # pseudo multimodal futures (GSPS's, `jaxmotion.models.gsps.pseudo_futures`: candidates every
    # `mm_candidate_stride` training frames, last observed pose within `mm_his_threshold` and future at
    # least `mm_pred_threshold` away, mean per-joint distances) keeps its history and takes one of them,
    # uniformly, as its future with this probability (the release: 2/3). 0 (default): the windows as drawn.
    cvae_pseudo_prob: float = 0.0
    mm_candidate_stride: int = 20  # the release's Human3.6M values (HumanEva-I: every 15 frames, future >= 0.01 m)
    mm_his_threshold: float = 0.05
    mm_pred_threshold: float = 0.1
    # Sampler (supp. Table 3).
    sampler_residual: int = 2  # 1 + 2 * 2 = 5 GCL-BN-Tanh layers in N_beta
    num_bases: int = 40  # M
    base_dim: int = 128  # n_b
    nh: int = 64  # hidden width of the two N_gamma MLPs
    base_tanh: bool = True  # Linear-BN-Tanh to B (the HumanEva-I code's first commit had no Tanh; the final release keeps it)
    coefficients: str = "gumbel"  # "gumbel" | "uniform" | "gaussian" (ablation, Table 5)
    pi: str = "uniform"  # "uniform" (1/M) | "learned_shared" | "learned_per_sample"
    tau: float = 1.0  # the paper's temperature; the released configs use 0.85
    # Sampler training (release: lr 1e-3, batch 16, K 50, 1500 epochs of which 100 at constant lr).
    nk: int = 50  # K while training; any K can be drawn afterwards
    lr: float = 1e-3
    batch_size: int = 16
    num_steps: int = 400
    lr_fix_fraction: float = 100 / 1500
    lambda_kl: float = 0.5
    lambda_acc: float = 40.0
    lambda_div: float = 20.0
    eta: float = 25.0  # hinge threshold on ||vec(y_i) - vec(y_j)||, metres over the whole t_pred x D future
    diversity: str = "hinge"  # "hinge" (Eq. (13)) | "exp" (DLow's exp(-D^2 / d_scale), ablation)
    d_scale: float = 50.0  # exp diversity scale (the release's `dlow_scale`)

    def __post_init__(self):  # the settings check themselves: a bad value fails where it is written
        check_config(self)


def check_config(c: DivSampConfig) -> DivSampConfig:
    """Returns `c` after checking its choices, raising a ValueError that names the bad field."""
    if not isinstance(c, DivSampConfig):
        raise TypeError(f"Config.method_config must be a jaxmotion.models.divsamp.DivSampConfig, got {type(c).__name__}")
    if c.coefficients not in COEFFICIENT_KINDS:
        raise ValueError(f"DivSampConfig.coefficients must be one of {COEFFICIENT_KINDS}, got {c.coefficients!r}")
    if c.pi not in PI_KINDS:
        raise ValueError(f"DivSampConfig.pi must be one of {PI_KINDS}, got {c.pi!r}")
    if c.pi != "uniform" and c.coefficients != "gumbel":
        raise ValueError(f"DivSampConfig.pi={c.pi!r} needs coefficients='gumbel', got {c.coefficients!r}")
    if c.diversity not in DIVERSITY_KINDS:
        raise ValueError(f"DivSampConfig.diversity must be one of {DIVERSITY_KINDS}, got {c.diversity!r}")
    for name in ("n_dct", "hidden", "nz", "num_bases", "base_dim", "nh", "nk", "batch_size", "cvae_batch_size"):
        if getattr(c, name) < 1:
            raise ValueError(f"DivSampConfig.{name} must be >= 1, got {getattr(c, name)}")
    if c.nk < 2:
        raise ValueError(f"DivSampConfig.nk must be >= 2 (the diversity loss needs pairs), got {c.nk}")
    if c.cvae_lambda_angle < 0:
        raise ValueError(f"DivSampConfig.cvae_lambda_angle must be >= 0, got {c.cvae_lambda_angle}")
    if not 0.0 <= c.cvae_pseudo_prob <= 1.0:
        raise ValueError(f"DivSampConfig.cvae_pseudo_prob must be in [0, 1], got {c.cvae_pseudo_prob}")
    if c.mm_candidate_stride < 1 or c.angle_bounds_frames < 1:
        raise ValueError(f"DivSampConfig.mm_candidate_stride and angle_bounds_frames must be >= 1, got "
                         f"{c.mm_candidate_stride}, {c.angle_bounds_frames}")
    if not 0.0 <= c.angle_percentile < 50.0:
        raise ValueError(f"DivSampConfig.angle_percentile must be in [0, 50), got {c.angle_percentile}")
    if c.tau <= 0:
        raise ValueError(f"DivSampConfig.tau must be > 0, got {c.tau}")
    return c


# --------------------------------------------------------------------------------------------
# Networks.


class DivSampCVAE(nn.Module):
    """DivSamp's GCN CVAE on DCT node features; `__call__` returns `(nodes_rec, mu, logvar)`."""

    n_dct: int = 10
    hidden: int = 256
    nz: int = 64
    num_residual: int = 4
    execution: Execution = Execution()  # how it runs (precision, the GCL stacks' layout): nn/execution.py

    def setup(self):
        mm, nm = self.execution.precision, self.execution.gcn_node_major
        bn = self.execution.batch_norm == "per_device"
        self.enc = GCLStack(self.hidden, self.num_residual, precision=mm, node_major=nm, per_device_bn=bn)
        self.e_mu = Dense(self.nz, precision=mm)
        self.e_logvar = Dense(self.nz, precision=mm)
        self.dec = GCLStack(self.hidden, self.num_residual, precision=mm, node_major=nm, per_device_bn=bn)
        self.d_out = GraphConv(3 * self.n_dct, precision=mm)

    def encode(self, cx: Float[ArrayLike, "b j c"], cw: Float[ArrayLike, "b j c"], *, train: bool):
        """Returns `(mu, logvar)` of q(z | X, Y) from the coefficients of the padded history and of the window."""
        h = self.enc(jnp.concatenate([cx, cw], axis=-1), train=train)
        h = h.reshape(h.shape[0], -1)
        return self.e_mu(h), self.e_logvar(h)

    def decode(self, cx: Float[ArrayLike, "b j c"], z: Float[ArrayLike, "b z"], *, train: bool) -> Float[Array, "b j c"]:
        """Returns the window's DCT node features for latents `z`: `cx + GCN([cx, z])`."""
        zj = jnp.broadcast_to(z[:, None, :], (z.shape[0], cx.shape[1], z.shape[-1]))
        h = self.dec(jnp.concatenate([cx, zj], axis=-1), train=train)
        return self.d_out(h) + cx

    def __call__(self, cx, cw, key: jax.Array | None = None, *, train: bool):
        """Returns `(nodes_rec, mu, logvar)`; z by reparameterisation when `key` is given, else z = mu."""
        mu, logvar = self.encode(cx, cw, train=train)
        return self.decode(cx, reparameterise(mu, logvar, key), train=train), mu, logvar


class GammaHead(nn.Module):
    """Returns `Dense(tanh(BN(Dense(p))))`: one N_gamma MLP (Linear-BN-Tanh-Linear, supp. Table 3)."""

    nh: int
    out: int
    precision: str = "float32"  # the products' (nn/precision.py)
    per_device_bn: bool = False  # BatchNorm.per_device

    @nn.compact
    def __call__(self, p: Float[ArrayLike, "... n"], *, train: bool) -> Float[Array, "... o"]:
        h = Dense(self.nh, precision=self.precision, name="dense_0")(p)
        # Statistics over all leading axes, i.e. over the b * K points, like the release's
        # BatchNorm1d on the (b * nk, n_b) matrix.
        h = BatchNorm(not train, 0.9, 1e-5, per_device=self.per_device_bn, name="bn")(h)
        return Dense(self.out, precision=self.precision, name="dense_1")(jnp.tanh(h))


class DivSampSampler(nn.Module):
    """DivSamp's sampler (N_beta, coefficients, N_gamma); returns `(z (b, K, nz), mean, logvar)` for K points."""

    nz: int = 64
    hidden: int = 256
    num_residual: int = 2
    num_bases: int = 40
    base_dim: int = 128
    nh: int = 64
    base_tanh: bool = True
    coefficients: str = "gumbel"
    pi: str = "uniform"
    tau: float = 1.0
    execution: Execution = Execution()  # as DivSampCVAE.execution; the coefficients' product w @ B stays float32

    @nn.compact
    def __call__(self, cx: Float[ArrayLike, "b j c"], key: jax.Array, k: int, *, train: bool, shared_eps: bool = True):
        """Returns `(z, mean, logvar)`; `eps` is one draw per window shared by its K latents (training, the release),
        or K independent draws with `shared_eps=False` (the release at test time)."""
        b = cx.shape[0]
        m = self.num_bases
        mm = self.execution.precision
        bn = self.execution.batch_norm == "per_device"
        h = GCLStack(self.hidden, self.num_residual, precision=mm, node_major=self.execution.gcn_node_major,
                     per_device_bn=bn, name="condition_enc")(cx, train=train)
        h = h.reshape(b, -1)
        base = Dense(m * self.base_dim, precision=mm, name="bases")(h)
        base = BatchNorm(not train, 0.9, 1e-5, per_device=bn, name="bases_bn")(base)
        if self.base_tanh:
            base = jnp.tanh(base)
        base = base.reshape(b, m, self.base_dim)  # B, one per window (DivSamp Eq. (8))
        if self.pi == "uniform":
            logits = jnp.zeros((b, m), jnp.float32)
        elif self.pi == "learned_shared":
            logits = jnp.broadcast_to(self.param("pi_logits", nn.initializers.zeros, (m,)), (b, m))
        elif self.pi == "learned_per_sample":
            logits = nn.Dense(m, name="pi_head", kernel_init=nn.initializers.zeros)(h)
        else:
            raise ValueError(f"DivSampSampler.pi must be one of {PI_KINDS}, got {self.pi!r}")
        k_w, k_eps = jax.random.split(key)
        if self.pi == "uniform":
            sample = lambda kk, _lg: sample_coefficients(kk, k, m, kind=self.coefficients, tau=self.tau)
        else:
            sample = lambda kk, lg: sample_coefficients(kk, k, m, kind=self.coefficients, tau=self.tau, logits=lg)
        w = jax.vmap(sample)(batch_rows(lambda n: jax.random.split(k_w, n), b), logits)  # (b, K, M), rows on the simplex
        p = w @ base  # (b, K, n_b): K points of the auxiliary space (DivSamp Eq. (11))
        mean = GammaHead(self.nh, self.nz, mm, bn, name="mean")(p, train=train)
        logvar = GammaHead(self.nh, self.nz, mm, bn, name="logvar")(p, train=train)
        eps = batch_rows(lambda n: jax.random.normal(k_eps, (n, 1 if shared_eps else k, self.nz)), b)
        return jnp.exp(0.5 * logvar) * eps + mean, mean, logvar  # DivSamp Eq. (12)


def cvae_from_config(c: DivSampConfig, execution: Execution = Execution()) -> DivSampCVAE:
    """Returns the CVAE module a `DivSampConfig` describes, run as `execution` says (nn/execution.py)."""
    return DivSampCVAE(n_dct=c.n_dct, hidden=c.hidden, nz=c.nz, num_residual=c.cvae_residual, execution=execution)


def sampler_from_config(c: DivSampConfig, execution: Execution = Execution()) -> DivSampSampler:
    """Returns the sampler module a `DivSampConfig` describes, run as `execution` says (nn/execution.py)."""
    return DivSampSampler(
        nz=c.nz, hidden=c.hidden, num_residual=c.sampler_residual, num_bases=c.num_bases, base_dim=c.base_dim,
        nh=c.nh, base_tanh=c.base_tanh, coefficients=c.coefficients, pi=c.pi, tau=c.tau, execution=execution,
    )


# --------------------------------------------------------------------------------------------
# Samplers.


def decode_k(cvae: DivSampCVAE, variables, cx: Float[ArrayLike, "b j c"], z: Float[ArrayLike, "b k z"], *, t_his: int, t_pred: int):
    """Returns the `(b, K, t_pred, D)` futures decoded from latents `z` (BatchNorm in evaluation mode).

    K is folded into the batch: one decoder call on `b * K` rows, each window's conditioning
    repeated K times. In evaluation mode BatchNorm is a fixed per-feature affine map, so every
    row is decoded exactly as alone (tested equal to decoding each `z[:, k]` separately). A
    `jax.vmap` over K computes the same numbers more slowly on XLA:CPU (the batched axis then sits
    in front of the GCL stacks' node-major layout, nn/gcn.py): folded, the sampler's training step
    measured 1.22x faster, K = 50 sampling 1.16x-1.26x and the K = 1000 evaluation 31 -> 27 s
    (benchmarks/results/optimisations.md, "DivSamp's K futures folded into the batch").
    """
    b, k = z.shape[:2]
    nodes = cvae.apply(variables, jnp.repeat(cx, k, axis=0), z.reshape((b * k,) + z.shape[2:]), train=False, method=DivSampCVAE.decode)
    return from_nodes(nodes, t_his + t_pred)[:, t_his:].reshape(b, k, t_pred, -1)


def sample_prior(cvae: DivSampCVAE, variables, x: Float[ArrayLike, "b t_his d"], key, k: int, *, t_pred: int):
    """Returns K futures `(b, K, t_pred, D)` with latents drawn i.i.d. from N(0, I): the plain CVAE baseline.

    Args:
        cvae: DivSamp's GCN CVAE.
        variables: its trained variables (parameters and BatchNorm statistics).
        x: observed frames `(b, t_his, D)`, metres, root-relative.
        key: a `jax.random` key.
        k: the number of futures K.
        t_pred: the number of future frames.
    """
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    z = batch_rows(lambda n: jax.random.normal(key, (n, k, cvae.nz)), x.shape[0])
    return decode_k(cvae, variables, cx, z, t_his=x.shape[1], t_pred=t_pred)


def sample_divsamp(
    cvae: DivSampCVAE, cvae_variables, sampler: DivSampSampler, sampler_variables, x: Float[ArrayLike, "b t_his d"], key, k: int,
    *, t_pred: int,
):
    """Returns DivSamp's K futures `(b, K, t_pred, D)` (Alg. 2): K auxiliary points -> K Gaussians -> K latents -> decoder.

    Each of the K latents has its own noise draw, as the release's evaluation does (training shares
    one per window, `DivSampSampler`'s `shared_eps`).

    Args:
        cvae: the trained GCN CVAE (frozen).
        cvae_variables: its variables.
        sampler: the Gumbel-Softmax sampler; any K, not only the trained one.
        sampler_variables: its variables.
        x: observed frames `(b, t_his, D)`, metres, root-relative.
        key: a `jax.random` key.
        k: the number of futures K.
        t_pred: the number of future frames.
    """
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    z, _, _ = sampler.apply(sampler_variables, cx, key, k, train=False, shared_eps=False)
    return decode_k(cvae, cvae_variables, cx, z, t_his=x.shape[1], t_pred=t_pred)


# --------------------------------------------------------------------------------------------
# Objectives. Each returns `(loss, (metrics, new_batch_stats))`.


def cvae_loss(
    cvae: DivSampCVAE, variables, batch: Float[ArrayLike, "b t d"], key, *, t_his: int, parents: tuple[int, ...],
    beta: float, lambda_v: float, lambda_his: float, lambda_limb: float,
    lambda_angle: float = 0.0, angle_bounds=None, roles: dict[str, int] | None = None,
):
    """Returns the CVAE objective of the release's `run_cvae.py` and the updated BatchNorm statistics.

    loss = ||Y_rec - Y||^2 + lambda_v ||x_{t_his} - y_rec_1||^2 + beta KL(q || N(0, I))
           + lambda_his mean_t ||X_rec_t - X_t||^2 + lambda_limb mean_t sum_bones (l_t - l_0)^2
           [+ lambda_angle angle_loss(predicted future frames)],
    squared norms summed over frames and dims and averaged over the batch, l_0 the bone lengths
    of the first observed frame. The release penalises joint angles outside ranges it reads from a
    dataset-specific file (`h36m_valid_angle.p`, not distributed); with `lambda_angle > 0` the term is
    GSPS's `angle_loss` under `angle_bounds` (measured on the training poses) for the joint `roles`.
    """
    t_pred = batch.shape[1] - t_his
    x, y = batch[:, :t_his], batch[:, t_his:]
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    cw = to_nodes(batch, cvae.n_dct)
    (nodes, mu, logvar), upd = cvae.apply(variables, cx, cw, key, train=True, mutable=["batch_stats"])
    rec = from_nodes(nodes, batch.shape[1])
    b = batch.shape[0]
    recon = jnp.sum((rec[:, t_his:] - y) ** 2) / b
    jump = jnp.sum((x[:, -1] - rec[:, t_his]) ** 2) / b
    kld = jnp.sum(kld_normal(mu, logvar)) / b
    his = jnp.mean(jnp.sum((rec[:, :t_his] - x) ** 2, axis=-1))
    limb = jnp.mean(jnp.sum((bone_lengths(rec, parents) - bone_lengths(batch[:, :1], parents)) ** 2, axis=-1))
    loss = recon + lambda_v * jump + beta * kld + lambda_his * his + lambda_limb * limb
    metrics = {"recon": recon, "jump": jump, "kld": kld, "his": his, "limb": limb}
    if lambda_angle > 0:
        future = rec[:, t_his:]
        ang = gsps.angle_loss(gsps.angle_cosines(future.reshape(-1, future.shape[-1]), roles), angle_bounds)
        loss = loss + lambda_angle * ang
        metrics["angle"] = ang
    return loss, (metrics, upd["batch_stats"])


def sampler_loss(
    sampler: DivSampSampler, variables, cvae: DivSampCVAE, cvae_variables, batch: Float[ArrayLike, "b t d"], key, *,
    t_his: int, k: int, lambda_kl: float, lambda_acc: float, lambda_div: float, eta: float,
    diversity: Literal["hinge", "exp"] = "hinge", d_scale: float = 50.0,
):
    """Returns DivSamp's sampler objective (Eq. (13)-(16)) on the frozen decoder, and the new BatchNorm statistics.

    loss = lambda_div mean_{i != j} max(0, eta - ||y_i - y_j||)            (Eq. (13), hinge diversity)
         + lambda_acc min_k ||y_k - Y||^2                                  (Eq. (14), accuracy)
         + lambda_kl mean_k KL(N(b_k, A_k^2) || N(0, I))                   (Eq. (15))
    each averaged over the batch. With `diversity="exp"` the first term is DLow's
    mean_{i<j} exp(-||y_i - y_j||^2 / d_scale) instead (the paper's hinge-vs-energy ablation).
    """
    t_pred = batch.shape[1] - t_his
    x, y = batch[:, :t_his], batch[:, t_his:]
    cx = condition_nodes(x, t_pred, cvae.n_dct)
    (z, mean, logvar), upd = sampler.apply(variables, cx, key, k, train=True, mutable=["batch_stats"])
    y_k = decode_k(cvae, jax.lax.stop_gradient(cvae_variables), cx, z, t_his=t_his, t_pred=t_pred)
    kld = jnp.mean(kld_normal(mean, logvar))
    acc = jnp.mean(jnp.min(jnp.sum((y_k - y[:, None]) ** 2, axis=(-2, -1)), axis=-1))
    if diversity == "hinge":
        div = jnp.mean(jax.vmap(lambda yk: hinge_diversity(yk, eta))(y_k))
    elif diversity == "exp":
        div = jnp.mean(jax.vmap(lambda yk: dlow_diversity(yk, d_scale))(y_k))
    else:
        raise ValueError(f"sampler_loss: diversity must be one of {DIVERSITY_KINDS}, got {diversity!r}")
    loss = lambda_div * div + lambda_acc * acc + lambda_kl * kld
    return loss, ({"div": div, "recon": acc, "kld": kld}, upd["batch_stats"])
