"""MotionMap (Hosseininejad, Shukla et al., CVPR 2025): a heatmap over future motions, modes ranked by confidence.

The method, in the order it is trained (paper Sec. 3-4, the authors' `code/` release):

1. An autoencoder of the future given the past. GRU encoders `E_X(X) = z_x`, `E_Y(Y) = z_y` (128),
   a fusion MLP `f = tanh(Lin(tanh(Lin([z_x, z_y]))))` (256), and a GRU-cell decoder that receives
   `f` at every step and reconstructs the whole window `[X, Y]`, residual to the first observed
   frame. Its target future is a random member of the window's multimodal ground truth, motion
   transferred onto the window's skeleton. An uncertainty head (MLP on the stopped-gradient `f`)
   predicts `log sigma` per joint per frame, trained by the heteroscedastic NLL (Eq. 1)
   `e / sigma^2 + log sigma^2` with the stopped squared error `e`.
2. The map: the `z_y` codes of training futures embedded in 2-D by t-SNE (openTSNE, fitted on a
   strided subset with perplexity 100, cosine metric, PCA initialisation, then every code
   transformed at perplexity 20), scaled into a square `size x size` grid and rounded to cells.
   The codebook maps a cell to the mean code of the futures in it; an empty cell takes the code
   of its nearest filled cell.
3. The heatmap model: a GRU over the last three observed frames (motion transferred onto a fixed
   template skeleton), an MLP to the flattened map, a stack of 1 x 1 convolutions; logits trained
   by weighted binary cross-entropy against Gaussian ground-truth maps (a bump of sigma ~2.8 cells
   at each multimodal future's cell, combined by a pixel-wise max).
4. Fine-tuning: the fusion MLP and decoder (and uncertainty head) learn to decode codebook codes.

Inference: local maxima of the predicted map (minimum distance, relative threshold), ranked by
confidence (the map's value at the peak); each peak's codebook code is decoded with X.

Everything below is a pure function or a Flax module; the stage wiring is `jaxmotion/methods/motionmap.py`.
Frame vectors drop the root ([protocol §1][representation]): joint `j` of a frame is skeleton joint `j + 1`, and
a link whose parent is the root starts at the origin.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Bool, Float, Int, Shaped

from jaxmotion.nn.batch import batch_rows
from jaxmotion.body.bones import frame_parents, motion_transfer  # noqa: F401 (re-exported)
from jaxmotion.nn.gru import GRU, GRUCell, gru_update
from jaxmotion.nn.linear import Conv1x1, Dense
from jaxmotion.nn.mlp import MLP


# --------------------------------------------------------------------------------------------
# Settings.


@dataclasses.dataclass(slots=True)
class MotionMapConfig:
    """MotionMap's settings (`Config.method_config` of method "motionmap"); defaults: the synthetic job.

    The release's values are noted where ours differ (its budget is 500 epochs per stage on a GPU).
    """

    nh_rnn: int = 128
    nh_fuse: int = 256
    nh_uncertainty: int = 256
    n_uncertainty_layers: int = 5
    hm_size: int = 64  # release: 128
    hm_sigma: float = 8.0**0.5  # release: covariance diag(8, 8)
    hm_channels: int = 8
    hm_convs: int = 6
    pos_weight: float = 10.0  # release `posWt`
    descriptor_frames: int = 3
    mm_threshold: float | None = None  # None: the dataset's threshold (protocol §4, docs/pages/protocol.md#datasets)
    max_members: int = 64  # multimodal futures drawn into one ground-truth map (a random subset of larger sets)
    # Members sharing a map cell draw the same bump: True keeps one member per cell before the cap, so a
    # set larger than `max_members` keeps as many distinct cells as it can (the release draws every member).
    dedupe_members: bool = False
    # The map's density. The release embeds every candidate window (Human3.6M: every 0.1 s) and fits
    # t-SNE on all of them: `pool_stride=3` at 30 fps and `tsne_fit_points=None`
    # (experiments/configs/motionmap_bandai_dense.py). These defaults keep the synthetic job's budget.
    pool_stride: int | None = None  # training windows every `pool_stride` frames (None: t_his)
    tsne_fit_points: int | None = 2000  # the strided subset openTSNE is fitted on (None: every training window, no transform)
    tsne_perplexity_fit: float = 100.0
    tsne_perplexity_transform: float = 20.0
    # "top_k" (ours): K futures, the top-K peaks repeated in confidence order when fewer. "release"
    # adds the predictor `motionmap_all_peaks`: the zero-velocity future and every peak (`all_peaks`),
    # with `distinct_futures` (its ANP plus one) in the records.
    k_protocol: str = "top_k"
    peak_min_distance: int = 5  # release `peak_interval`
    peak_threshold_rel: float = 0.35
    max_peaks: int = 49
    loss_scale: float = 10.0  # the release multiplies positions by 10 "for improved optimization"
    lr: float = 1e-3
    batch_size: int = 64
    ae_steps: int = 2000
    hm_steps: int = 1500
    ft_steps: int = 500
    mm_cache_dir: str | None = None  # where MM ground-truth sets are cached (None: not cached)

    def __post_init__(self):  # the settings check themselves: a bad value fails where it is written
        if self.k_protocol not in ("top_k", "release"):
            raise ValueError(f"MotionMapConfig.k_protocol must be 'top_k' or 'release', got {self.k_protocol!r}")
        if self.descriptor_frames < 1 or self.hm_size < 8 or self.peak_min_distance < 1 or not 0 <= self.peak_threshold_rel < 1:
            raise ValueError(
                f"MotionMapConfig: need descriptor_frames >= 1, hm_size >= 8, peak_min_distance >= 1 and 0 <= "
                f"peak_threshold_rel < 1, got {self.descriptor_frames}, {self.hm_size}, {self.peak_min_distance}, "
                f"{self.peak_threshold_rel}"
            )


# Motion transfer (appendix A) is shared with evaluation: it lives with the skeleton's bones
# (`jaxmotion.body.bones.motion_transfer`) and is re-exported here. MotionMap's multimodal ground
# truth, built on it, is the evaluation protocol's (`jaxmotion.eval.metrics.motionmap_mm_sets`).


# --------------------------------------------------------------------------------------------
# The map: t-SNE, grid scaling, codebook, ground-truth heatmaps, peaks.


def tsne_embed(
    codes: Float[np.ndarray, "n c"], *, fit_points: int | None, perplexity_fit: float = 100.0,
    perplexity_transform: float = 20.0, seed: int = 0, n_jobs: int = 2,
) -> Float[np.ndarray, "n 2"]:
    """Returns 2-D t-SNE coordinates of every code: openTSNE fitted on a strided subset, then `transform` (release recipe).

    `fit_points=None` fits on every code and returns that embedding (no `transform`); openTSNE's
    FFT-accelerated gradients keep that affordable for tens of thousands of codes.

    Needs the optional dependency openTSNE (`pip install 'jaxmotion[motionmap]'`).
    """
    try:
        from openTSNE import TSNE
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("MotionMap's map needs openTSNE: pip install 'jaxmotion[motionmap]' (or pip install openTSNE)") from e
    codes = np.asarray(codes, np.float64)
    stride = 1 if fit_points is None else max(1, -(-codes.shape[0] // fit_points))
    sub = codes[::stride]
    perp = float(min(perplexity_fit, (sub.shape[0] - 1) / 3.0))
    tsne = TSNE(perplexity=perp, initialization="pca", metric="cosine", n_jobs=n_jobs, random_state=seed, verbose=False)
    emb = tsne.fit(sub)
    if fit_points is None:
        return np.asarray(emb, np.float32)
    out = emb.transform(codes, perplexity=float(min(perplexity_transform, perp)))
    return np.asarray(out, np.float32)


def grid_scaling(points: Float[np.ndarray, "n 2"], size: int, margin: float = 0.02) -> tuple[np.ndarray, float]:
    """Returns `(origin (2,), scale)` mapping points into a `size x size` grid, one scale for both axes, 2% margins, centred."""
    lo, hi = points.min(0), points.max(0)
    extent = float(np.max(hi - lo)) * (1 + 2 * margin) + 1e-12
    scale = (size - 1) / extent
    origin = (lo + hi) / 2 - extent / 2
    return origin.astype(np.float32), float(scale)


def to_cells(points: Float[Array, "*n 2"], origin, scale: float, size: int) -> Int[Array, "*n 2"]:
    """Returns the grid cell (row, col) of every point: `round((p - origin) * scale)`, clipped into the grid."""
    return jnp.clip(jnp.round((points - origin) * scale), 0, size - 1).astype(jnp.int32)


def build_codebook(
    cells: Int[np.ndarray, "n 2"], codes: Float[np.ndarray, "n c"], size: int
) -> tuple[Float[np.ndarray, "size size c"], Bool[np.ndarray, "size size"]]:
    """Returns `(table, filled)`: the mean code of the futures in each cell; an empty cell takes its nearest filled cell's.

    "Nearest" is Euclidean on the grid (the release searches breadth-first over 4-neighbours).
    """
    sums, counts = _cell_sums(cells, np.asarray(codes, np.float64), size)
    filled = counts > 0
    return _from_nearest_filled(sums / np.maximum(counts, 1)[..., None], filled).astype(np.float32), filled


def cell_label_counts(
    cells: Int[np.ndarray, "n 2"], labels: Int[np.ndarray, " n"], num_labels: int, size: int
) -> Int[np.ndarray, "size size l"]:
    """Returns how many futures of each label fall in each cell; an empty cell takes its nearest filled cell's counts.

    The cells carry the labels of the futures in them, filled as `build_codebook` fills the table,
    so a cell decodes the code of the same futures whose labels it carries.
    """
    labels = np.asarray(labels)
    if labels.shape != (len(cells),) or labels.min(initial=0) < 0 or labels.max(initial=0) >= num_labels:
        raise ValueError(f"cell_label_counts: need one label in [0, {num_labels}) per cell, got shape {labels.shape}")
    sums, counts = _cell_sums(cells, np.eye(num_labels, dtype=np.int64)[labels], size)
    return _from_nearest_filled(sums, counts > 0).astype(np.int32)


def _cell_sums(cells: Int[np.ndarray, "n 2"], values: Shaped[np.ndarray, "n c"], size: int):
    """Returns `(sums (size, size, c), counts (size, size))` of the values of the points in each cell."""
    cells = np.asarray(cells)
    flat = cells[:, 0] * size + cells[:, 1]
    sums = np.zeros((size * size, values.shape[1]), values.dtype)
    np.add.at(sums, flat, values)
    return sums.reshape(size, size, -1), np.bincount(flat, minlength=size * size).reshape(size, size)


def _from_nearest_filled(grid: np.ndarray, filled: Bool[np.ndarray, "size size"]) -> np.ndarray:
    """Returns `grid` with every empty cell's entry taken from its nearest filled cell (Euclidean on the grid)."""
    from scipy.ndimage import distance_transform_edt

    _, (ri, ci) = distance_transform_edt(~filled, return_indices=True)
    return grid[ri, ci]


def gaussian_heatmap(
    cells: Float[Array, "m 2"], mask: Bool[Array, " m"], size: int, sigma: float
) -> Float[Array, "size size"]:
    """Returns MotionMap's ground-truth map: the pixel-wise max of a Gaussian bump `exp(-|u - c|^2 / 2 sigma^2)` per valid cell."""
    u = jnp.arange(size, dtype=jnp.float32)
    # The bump is separable, exp(-dr^2 / 2 s^2) * exp(-dc^2 / 2 s^2): 2 * size exponentials per cell
    # instead of size^2 (equal to float32 rounding; a heatmap step draws 64 windows x 64 member bumps).
    rows = jnp.exp(-((u[None, :] - cells[:, 0, None]) ** 2) / (2 * sigma**2))  # (m, size)
    cols = jnp.exp(-((u[None, :] - cells[:, 1, None]) ** 2) / (2 * sigma**2))
    rows = jnp.where(mask[:, None], rows, 0.0)
    return jnp.max(rows[:, :, None] * cols[:, None, :], axis=0, initial=0.0)  # no cell: an empty map


class Peaks(NamedTuple):
    """Peaks of a batch of maps, ranked by confidence: `cells[b, :n_b]` are valid where `valid`."""

    cells: Int[Array, "b p 2"]
    confidence: Float[Array, "b p"]
    valid: Bool[Array, "b p"]


def find_peaks(
    hm: Float[Array, "b h w"], *, min_distance: int, threshold_rel: float, max_peaks: int
) -> Peaks:
    """Returns the local maxima of each map ranked by value (`skimage.feature.peak_local_max` as the release uses it).

    A cell is a peak when it equals the max over its `(2 r + 1)^2` neighbourhood (`r = min_distance`)
    and exceeds `threshold_rel * max(map)`; of peaks closer than `r` (Chebyshev, i.e. plateaus) only
    the higher-ranked is kept. Vectorised over maps, jittable; at most `max_peaks` per map.
    """
    b, h, w = hm.shape
    win = 2 * min_distance + 1
    pooled = lax.reduce_window(hm, -jnp.inf, lax.max, (1, win, win), (1, 1, 1), "SAME")
    top = jnp.max(hm, axis=(1, 2), keepdims=True)
    is_peak = (hm >= pooled) & (hm > threshold_rel * top)
    score = jnp.where(is_peak, hm, -jnp.inf).reshape(b, -1)
    p = min(max_peaks, h * w)
    vals, flat = lax.top_k(score, p)
    cells = jnp.stack([flat // w, flat % w], axis=-1)
    valid = jnp.isfinite(vals)

    def keep_step(i, keep):
        cheb = jnp.max(jnp.abs(cells - cells[:, i][:, None]), axis=-1)  # (b, p)
        blocked = jnp.any(keep & (cheb <= min_distance) & (jnp.arange(p) < i)[None], axis=-1)
        return keep.at[:, i].set(valid[:, i] & ~blocked)

    keep = lax.fori_loop(0, p, keep_step, jnp.zeros_like(valid))
    keep_sorted, cells, vals = kept_first(keep, keep, cells, vals)
    return Peaks(cells, jnp.where(keep_sorted, vals, 0.0), keep_sorted)


def kept_first(keep: Bool[Array, "b p"], *arrays: Array) -> tuple[Array, ...]:
    """Returns each `(b, p, ...)` array reordered along axis 1 so the kept entries come first, each group in its old order."""
    order = jnp.argsort(~keep, axis=-1, stable=True)
    return tuple(jnp.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1) for a in arrays)


def top_k_slots(valid: Bool[Array, "b p"], k: int) -> Int[Array, "b k"]:
    """Returns, per map, the peak index used for each of K outputs: the top-K peaks, then the ranking again from the best.

    With n < K peaks, output k takes peak `k mod n` (the modes repeated in confidence order); with
    no peak at all, peak 0 (whose cell is then the map's argmax region of a flat map).
    """
    n = jnp.maximum(jnp.sum(valid, axis=-1, keepdims=True), 1)
    return jnp.arange(k)[None] % n


# --------------------------------------------------------------------------------------------
# Losses.


def heteroscedastic_nll(err: Float[Array, "*s"], log_sigma: Float[Array, "*s"]) -> Float[Array, "*s"]:
    """Returns MotionMap's Eq. (1) `e / sigma^2 + log sigma^2` per element; minimised over sigma at `sigma^2 = e`."""
    return err * jnp.exp(-2.0 * log_sigma) + 2.0 * log_sigma


def weighted_bce(logits: Float[Array, "*s"], target: Float[Array, "*s"], pos_weight: float) -> Float[Array, "*s"]:
    """Returns `-(w t log s(l) + (1 - t) log(1 - s(l)))` per element (`torch.nn.BCEWithLogitsLoss(pos_weight=w)`)."""
    return -(pos_weight * target * jax.nn.log_sigmoid(logits) + (1 - target) * jax.nn.log_sigmoid(-logits))


# --------------------------------------------------------------------------------------------
# Networks.


class Decoder(nn.Module):
    """Returns `(b, t_total, dim)` frames: a GRU cell fed the fused code at every step, residual to `x0`."""

    dim: int
    t_total: int
    nh: int = 128

    @nn.compact
    def __call__(self, fused: Float[Array, "b f"], x0: Float[Array, "b d"]) -> Float[Array, "b t d"]:
        h0 = jnp.tanh(Dense(self.nh, name="h0")(fused))
        cell = GRUCell(self.nh, name="cell")
        cell(h0, fused)  # creates the parameters at init
        p = cell.variables["params"]
        gi = fused @ p["weight_ih"] + p["bias_ih"]  # the input never changes over time

        def step(h, _):
            h = gru_update(gi, h @ p["weight_hh"] + p["bias_hh"], h)
            return h, h

        _, hs = lax.scan(step, h0, None, length=self.t_total)
        return x0[:, None] + Dense(self.dim, name="out")(jnp.swapaxes(hs, 0, 1))


class MotionMapAE(nn.Module):
    """MotionMap's autoencoder with its uncertainty head; call its methods through `apply(..., method=...)`."""

    dim: int
    t_his: int
    t_pred: int
    nh_rnn: int = 128
    nh_fuse: int = 256
    nh_uncertainty: int = 256
    n_uncertainty_layers: int = 5

    def setup(self):
        # Dense layers and 1x1 convolutions initialised as the release's nn.Linear / nn.Conv2d (nn/linear.py).
        self.enc_x = GRU(self.nh_rnn)
        self.enc_y = GRU(self.nh_rnn)
        self.fusion = MLP((self.nh_fuse, self.nh_fuse))
        self.decoder = Decoder(self.dim, self.t_his + self.t_pred, self.nh_rnn)
        self.uncertainty = MLP((self.nh_uncertainty,) * self.n_uncertainty_layers, activation="elu")
        self.uncertainty_out = Dense((self.t_his + self.t_pred) * (self.dim // 3))

    def encode_x(self, x: Float[Array, "b t_his d"]) -> Float[Array, "b h"]:
        """Returns the history encoder's last hidden state."""
        return self.enc_x(x, last_only=True)

    def encode_y(self, y: Float[Array, "b t_pred d"]) -> Float[Array, "b h"]:
        """Returns the future encoder's last hidden state."""
        return self.enc_y(y, last_only=True)

    def decode(self, x: Float[Array, "b t_his d"], z_y: Float[Array, "b h"]):
        """Returns `(frames (b, t_his + t_pred, d), log_sigma (b, t_his + t_pred, d // 3))` from X and a future code."""
        fused = self.fusion(jnp.concatenate([self.encode_x(x), z_y], axis=-1))
        frames = self.decoder(fused, x[:, 0])
        ls = self.uncertainty_out(self.uncertainty(lax.stop_gradient(fused)))
        return frames, ls.reshape(x.shape[0], self.t_his + self.t_pred, self.dim // 3)

    def __call__(self, x: Float[Array, "b t_his d"], y: Float[Array, "b t_pred d"]):
        return self.decode(x, self.encode_y(y))


class HeatmapNet(nn.Module):
    """Returns `(b, size, size)` logits of the map from the last `frames` observed frames (the release's HeatmapDecoder)."""

    size: int
    nh_rnn: int = 128
    channels: int = 8
    n_convs: int = 6
    frames: int = 3

    @nn.compact
    def __call__(self, x: Float[Array, "b t d"]) -> Float[Array, "b size size"]:
        h = GRU(self.nh_rnn, name="context")(x[:, -self.frames :], last_only=True)
        h = nn.LayerNorm(name="norm")(nn.elu(h))
        m = nn.elu(Dense(self.size * self.size, name="to_map")(h)).reshape(-1, self.size, self.size, 1)

        for i in range(self.n_convs):
            m = nn.elu(Conv1x1(self.channels, name=f"conv_{i}")(m))
        return Conv1x1(1, name="final")(m)[..., 0]


def ae_model(c: MotionMapConfig, dim: int, t_his: int, t_pred: int) -> MotionMapAE:
    """Returns the autoencoder a `MotionMapConfig` describes."""
    return MotionMapAE(dim, t_his, t_pred, c.nh_rnn, c.nh_fuse, c.nh_uncertainty, c.n_uncertainty_layers)


def heatmap_model(c: MotionMapConfig) -> HeatmapNet:
    """Returns the heatmap network a `MotionMapConfig` describes."""
    return HeatmapNet(c.hm_size, c.nh_rnn, c.hm_channels, c.hm_convs, c.descriptor_frames)


def reconstruction_loss(
    frames: Float[Array, "b t d"], log_sigma: Float[Array, "b t j"], target: Float[Array, "b t d"], scale: float
):
    """Returns `(loss, metrics)`: per-joint squared error (positions x `scale`) plus the NLL of the uncertainty head on its stopped value."""
    b, t, d = frames.shape
    err = jnp.sum(((frames - target) * scale).reshape(b, t, d // 3, 3) ** 2, axis=-1)
    nll = heteroscedastic_nll(lax.stop_gradient(err), log_sigma)
    rec = jnp.mean(err)
    return rec + jnp.mean(nll), {"recon": rec, "nll": jnp.mean(nll), "sigma": jnp.mean(jnp.exp(log_sigma)) / scale}


def ae_loss(model: MotionMapAE, params, batch, *, scale: float):
    """Returns `(loss, metrics)` of stage 1: reconstruct `[X, Y_mm]` from X and `E_Y(Y_mm)`, plus the uncertainty NLL."""
    frames, ls = model.apply(params, batch["x"], batch["y"])
    return reconstruction_loss(frames, ls, jnp.concatenate([batch["x"], batch["y"]], axis=1), scale)


def finetune_loss(model: MotionMapAE, params, table: Float[Array, "g c"], batch, *, scale: float):
    """Returns `(loss, metrics)` of stage 4: reconstruct `[X, Y_mm]` from X and the codebook code of Y_mm's cell."""
    z = table[batch["cell"]]
    frames, ls = model.apply(params, batch["x"], z, method=MotionMapAE.decode)
    return reconstruction_loss(frames, ls, jnp.concatenate([batch["x"], batch["y"]], axis=1), scale)


def heatmap_loss(model: HeatmapNet, params, cells: Int[Array, "r 2"], batch, *, size: int, sigma: float, pos_weight: float):
    """Returns `(loss, metrics)` of stage 2: weighted BCE of the logits against the Gaussian maps of the MM futures' cells."""
    target = jax.vmap(lambda ix, mk: gaussian_heatmap(cells[ix].astype(jnp.float32), mk, size, sigma))(batch["members"], batch["mask"])
    logits = model.apply(params, batch["x"])
    loss = jnp.mean(weighted_bce(logits, target, pos_weight))
    return loss, {"bce": loss, "peak_prob": jnp.mean(jnp.max(jax.nn.sigmoid(logits), axis=(1, 2)))}


# --------------------------------------------------------------------------------------------
# Inference.


class Modes(NamedTuple):
    """A variable number of modes per window, ranked by confidence; entries past `n` are padding."""

    futures: Float[Array, "b p t d"]
    confidence: Float[Array, "b p"]
    sigma: Float[Array, "b p t j"]  # per-joint standard deviation (metres) of every future frame
    cells: Int[Array, "b p 2"]
    valid: Bool[Array, "b p"]
    heatmap: Float[Array, "b h w"]


def predict_modes(
    ae: MotionMapAE, ae_params, hm: HeatmapNet, hm_params, codebook: dict, x: Float[Array, "b t_his d"],
    parents: tuple[int, ...], *, min_distance: int, threshold_rel: float, max_peaks: int, scale: float,
) -> Modes:
    """Returns every window's modes: the peaks of its predicted map, each codebook code decoded with X."""
    desc = motion_transfer(x, codebook["template"], parents)
    heat = jax.nn.sigmoid(hm.apply(hm_params, desc))
    peaks = find_peaks(heat, min_distance=min_distance, threshold_rel=threshold_rel, max_peaks=max_peaks)
    futures, sigma = decode_cells(ae, ae_params, codebook["table"], x, peaks.cells, scale=scale)
    return Modes(futures, peaks.confidence, sigma, peaks.cells, peaks.valid, heat)


def decode_cells(
    ae: MotionMapAE, ae_params, table: Float[Array, "h w c"], x: Float[Array, "b t_his d"], cells: Int[Array, "b p 2"],
    *, scale: float,
) -> tuple[Float[Array, "b p t_pred d"], Float[Array, "b p t_pred j"]]:
    """Returns `(futures, sigma)`: the codebook code of every cell decoded with its window's X, sigma in metres."""
    b, p = cells.shape[:2]
    z = table[cells[..., 0], cells[..., 1]]  # (b, p, c)
    frames, ls = ae.apply(ae_params, jnp.repeat(x, p, axis=0), z.reshape(b * p, -1), method=MotionMapAE.decode)
    t_his = x.shape[1]
    futures = frames[:, t_his:].reshape(b, p, -1, x.shape[-1])
    sigma = (jnp.exp(ls[:, t_his:]) / scale).reshape(b, p, -1, ls.shape[-1])
    return futures, sigma


def select_k(modes: Modes, k: int) -> Float[Array, "b k t d"]:
    """Returns K futures per window: the top-K modes by confidence, repeated in confidence order when fewer (`top_k_slots`)."""
    slots = top_k_slots(modes.valid, k)
    return jnp.take_along_axis(modes.futures, slots[..., None, None], axis=1)


def all_peaks(modes: Modes, x: Float[Array, "b t_his d"]) -> Float[Array, "b q t d"]:
    """Returns the release's K protocol: the zero-velocity future, then every valid peak's future (`q = max_peaks + 1`).

    The release scores a window on a variable set, the zero-velocity future and all its peaks, and
    reports the average number of peaks (ANP). Padding slots repeat the zero-velocity future, so
    every min-over-samples metric (ADE, FDE, MMADE, MMFDE) equals the release's on its variable set;
    APD and the medians over samples are not part of that protocol.
    """
    b, _, t, d = modes.futures.shape
    zv = jnp.broadcast_to(x[:, None, -1:, :], (b, 1, t, d))
    return jnp.concatenate([zv, jnp.where(modes.valid[..., None, None], modes.futures, zv)], axis=1)


def distinct_futures(pred: Float[np.ndarray, "n k t d"]) -> Int[np.ndarray, " n"]:
    """Returns how many different futures each window's K samples hold (equal bits count once)."""
    p = np.asarray(pred).reshape(pred.shape[0], pred.shape[1], -1)
    return np.asarray([np.unique(w, axis=0).shape[0] for w in p])


# --------------------------------------------------------------------------------------------
# Controllability: modes by action label, futures near a chosen mode.


def select_label(modes: Modes, label_counts: Int[Array, "h w l"], label: int | Int[Array, ""]) -> Modes:
    """Returns `modes` restricted to the peaks whose cell's majority label is `label`, first, still ranked by confidence.

    A cell's majority label is the most frequent label of the training futures in it (ties: the
    lower label index). Peaks of other labels become padding (`valid` False, confidence 0); a window
    with no peak of that label has no valid mode at all (`valid[b].any()` is False): its map puts
    no mode of that action near the observed motion. Jittable; `label` may be traced.
    """
    majority = jnp.argmax(label_counts, axis=-1)[modes.cells[..., 0], modes.cells[..., 1]]  # (b, p)
    keep = modes.valid & (majority == label)
    futures, confidence, sigma, cells, keep = kept_first(keep, modes.futures, modes.confidence, modes.sigma, modes.cells, keep)
    return Modes(futures, jnp.where(keep, confidence, 0.0), sigma, cells, keep, modes.heatmap)


def disc_cells(key: jax.Array, centre: Int[Array, "b 2"], *, k: int, radius: float, size: int) -> Int[Array, "b k 2"]:
    """Returns K random grid cells per window, uniform over the cells within `radius` of `centre`, clipped into the grid.

    Clipping moves a cell towards the (in-grid) centre, so every cell stays within `radius`; cells
    at the grid's edge are then the likelier. `radius = 0`: the centre K times.
    """
    r = int(np.floor(radius))
    off = np.stack(np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="ij"), -1).reshape(-1, 2)
    off = jnp.asarray(off[(off**2).sum(-1) <= radius**2], jnp.int32)
    pick = batch_rows(lambda n: jax.random.randint(key, (n, k), 0, off.shape[0]), centre.shape[0])
    return jnp.clip(centre[:, None] + off[pick], 0, size - 1)


class NearSamples(NamedTuple):
    """K futures per window decoded from codebook cells near a chosen mode."""

    futures: Float[Array, "b k t d"]
    sigma: Float[Array, "b k t j"]
    cells: Int[Array, "b k 2"]


def sample_near_mode(
    ae: MotionMapAE, ae_params, table: Float[Array, "h w c"], x: Float[Array, "b t_his d"], centre: Int[Array, "b 2"],
    key: jax.Array, *, k: int, radius: float, scale: float,
) -> NearSamples:
    """Returns K futures per window decoded from random codebook cells within `radius` cells of `centre` (`disc_cells`).

    `centre` is a chosen mode's cell (`Modes.cells[:, rank]`): neighbouring cells hold the codes of
    nearby futures on the map, so the samples are variations of that mode.
    """
    cells = disc_cells(key, centre, k=k, radius=radius, size=table.shape[0])
    futures, sigma = decode_cells(ae, ae_params, table, x, cells, scale=scale)
    return NearSamples(futures, sigma, cells)
