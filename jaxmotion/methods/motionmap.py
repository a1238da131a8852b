"""MotionMap as a method: autoencoder, map and codebook, heatmap model, fine-tuning (MotionMap Sec. 3-4).

Settings: `Config.method_config`, a `jaxmotion.models.motionmap.MotionMapConfig`. Stages:
`autoencoder` (reconstruct `[X, Y_mm]`, uncertainty NLL), `codebook` (computed, `num_steps=0`:
t-SNE of the training futures' `E_Y` codes, cells, mean code per cell), `heatmap` (weighted BCE
against Gaussian maps of the multimodal futures' cells), `finetune` (fusion MLP, decoder and
uncertainty head decode codebook codes; the encoders stay as stage 1 left them).

Training windows: the "pool", every `pool_stride` (default `t_his`) frames of every training
sequence. Each pool window's multimodal ground truth is MotionMap's (`motionmap_mm_sets`: last
three observed frames, candidates motion-transferred onto its skeleton) over the pool itself;
every training target future is such a member, motion-transferred onto the window's skeleton.

Predictors: zero-velocity and `motionmap` (K futures: the top-K peaks of the predicted map by
confidence; with fewer peaks than K the peaks are repeated in confidence order, so the K outputs
hold every mode once before any repeats). `modes_fn` gives the variable number of modes with their
confidences and per-joint uncertainties. Evaluation's multimodal ground truth comes from the
training windows (`reference_futures="train"`, MotionMap Tables 1-2).

Controllability: the codebook's cells carry the action labels of the training futures in them
(`label_counts`, `future_labels`); `label_modes_fn` keeps the modes of one action, `near_mode_fn`
samples futures from the cells around a chosen mode. Pictures (`draw_pictures`, drawn by
`jaxmotion run` through `Method.pictures`): the predicted and true maps, the ranked modes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion.eval import metrics
from jaxmotion.data.windows import test_windows
from jaxmotion.method import ExtraMetrics, Method, Stage
from jaxmotion.methods.common import zero_velocity
from jaxmotion.models import motionmap as mm
from jaxmotion.models.motionmap import MotionMapConfig


def settings(cfg) -> MotionMapConfig:
    """Returns `cfg.method_config` (the defaults when it is None); `MotionMapConfig` checks itself when made."""
    return METHOD.settings(cfg)


class Pool:
    """The training windows every `stride` frames and their MotionMap multimodal ground truth (computed on first use)."""

    def __init__(self, prep, c: MotionMapConfig):
        ds = prep.dataset
        if prep.train_frames is None:
            raise ValueError(f"MotionMap on {ds.name!r}: needs joint (root-relative) frames, not marker frames")
        self.ds, self.c = ds, c
        self.parents = tuple(ds.skeleton.parents)
        mm.frame_parents(self.parents)  # a skeleton motion transfer cannot handle is an error now
        stride = c.pool_stride or ds.t_his
        self.windows, self.seq_index, self.starts = test_windows(prep.train_frames, ds.t_his, ds.t_pred, step=stride)
        self.thr = float(c.mm_threshold if c.mm_threshold is not None else ds.mm_threshold)
        self._sets = None
        self._transfer = jax.jit(lambda src, tgt: mm.motion_transfer(src, tgt[:, None], self.parents))

    @property
    def x(self) -> np.ndarray:
        return self.windows[:, : self.ds.t_his]

    @property
    def y(self) -> np.ndarray:
        return self.windows[:, self.ds.t_his :]

    @property
    def labels(self) -> np.ndarray:
        """Returns the action label (a string) of every pool window's future (`future_labels`)."""
        return future_labels(self.ds, self.seq_index, self.starts)

    @property
    def sets(self) -> tuple[np.ndarray, np.ndarray]:
        if self._sets is None:
            s = metrics.motionmap_mm_sets(
                self.x[:, -self.c.descriptor_frames :], self.thr, self.parents, cache_dir=self.c.mm_cache_dir
            )
            self._sets = (np.asarray(s.idx), np.asarray(s.mask))
        return self._sets

    def members(self, rng: np.random.Generator, j: np.ndarray) -> np.ndarray:
        """Returns one random multimodal member `(n,)` of each pool window `j` `(n,)`."""
        idx, mask = self.sets
        counts = mask[j].sum(1)
        return idx[j, (rng.random(len(j)) * counts).astype(int)]

    def targets(self, j: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Returns the futures `(n, t_pred, d)` of members `m` `(n,)` motion-transferred onto the skeletons of windows `j` `(n,)`."""
        return np.asarray(self._transfer(jnp.asarray(self.y[m]), jnp.asarray(self.x[j, -1])))

    def member_subsets(
        self, rng: np.random.Generator, j: np.ndarray, cap: int, cells: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Returns `(members (b, cap), mask)`: each window's set, or a random `cap` of it when larger.

        With `cells` (the map cell of every pool window) one member per cell is kept first, in a
        random order, so the cap drops repeated bumps before distinct ones (`dedupe_members`).
        """
        idx, mask = self.sets
        out, ok = np.zeros((len(j), cap), np.int32), np.zeros((len(j), cap), bool)
        for b, w in enumerate(j):
            s = idx[w, mask[w]]
            if cells is not None:
                s = rng.permutation(s)
                _, first = np.unique(cells[s], axis=0, return_index=True)
                s = s[np.sort(first)]
            if len(s) > cap:
                s = rng.choice(s, cap, replace=False)
            out[b, : len(s)], ok[b, : len(s)] = s, True
        return out, ok


def future_labels(ds, seq_index: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Returns the action label of the future of each training window `(ds.train[seq_index], starts)`.

    A sequence's `action` (Bandai-Namco-2: its content label, `walk`, `wave-left-hand`, ...), except
    where the dataset labels its segments (the synthetic data, whose sequences are all "mixed":
    `info["train_segments"]`): the action of the future's last frame, i.e. the mode it follows.
    """
    info = ds.info
    if "train_segments" in info and "mode_names" in info:
        last = starts + ds.t_total - 1
        seg = [info["train_segments"][q][f // info["segment_len"]] for q, f in zip(seq_index, last)]
        return np.asarray([info["mode_names"][a] for a in seg])
    return np.asarray([ds.train[q].action for q in seq_index])


def _encode_names(names) -> np.ndarray:
    """Returns label names as a `(l, n)` uint8 array of UTF-8 bytes, zero-padded (a checkpoint holds arrays, not strings)."""
    raw = [n.encode() for n in names]
    out = np.zeros((len(raw), max([1, *map(len, raw)])), np.uint8)
    for i, r in enumerate(raw):
        out[i, : len(r)] = np.frombuffer(r, np.uint8)
    return out


def _decode_names(arr) -> list[str]:
    return [bytes(row[row > 0]).decode() for row in np.asarray(arr, np.uint8)]


def _adam(c: MotionMapConfig, steps: int):
    # The release uses Adam (amsgrad) with ReduceLROnPlateau; here a cosine decay over the stage's fixed budget.
    return optax.amsgrad(optax.cosine_decay_schedule(c.lr, max(steps, 1), alpha=0.05))


def _codebook(ae: mm.MotionMapAE, ae_params, pool: Pool, c: MotionMapConfig, seed: int) -> dict:
    """Returns the codebook stage's parameters: map table, pool cells and codes, template skeleton, label counts per cell."""
    enc = jax.jit(lambda y: ae.apply(ae_params, y, method=mm.MotionMapAE.encode_y))
    y = pool.y
    codes = np.concatenate([np.asarray(enc(jnp.asarray(y[s : s + 512]))) for s in range(0, len(y), 512)])
    pts = mm.tsne_embed(
        codes, fit_points=c.tsne_fit_points, perplexity_fit=c.tsne_perplexity_fit,
        perplexity_transform=c.tsne_perplexity_transform, seed=seed,
    )
    origin, scale = mm.grid_scaling(pts, c.hm_size)
    cells = np.asarray(mm.to_cells(jnp.asarray(pts), jnp.asarray(origin), scale, c.hm_size))
    table, filled = mm.build_codebook(cells, codes, c.hm_size)
    print(f"motionmap codebook: {len(codes)} training futures in {int(filled.sum())} of {c.hm_size**2} cells", flush=True)
    return {
        "table": jnp.asarray(table), "cells": jnp.asarray(cells, jnp.int32), "codes": jnp.asarray(codes),
        "template": jnp.asarray(pool.x[0, -1]), "points": jnp.asarray(pts), **_label_fields(cells, pool.labels, c.hm_size),
    }


def _label_fields(cells: np.ndarray, labels: np.ndarray, size: int) -> dict:
    """Returns the codebook's `label_counts (size, size, l)` and `label_names` (encoded) for the pool's future labels."""
    names, idx = np.unique(labels, return_inverse=True)
    return {
        "label_counts": jnp.asarray(mm.cell_label_counts(cells, idx, len(names), size)),
        "label_names": jnp.asarray(_encode_names(names)),
    }


def _finetune_labels(params):
    # Stage 4 trains what decodes a code (fusion, decoder, uncertainty head); the encoders stay fixed.
    return {"params": {k: ("freeze" if k in ("enc_x", "enc_y") else "train") for k in params["params"]}}


def stages(cfg, prep) -> list[Stage]:
    """Returns MotionMap's stages: autoencoder, codebook (computed), heatmap, finetune."""
    ds, c = prep.dataset, settings(cfg)
    pool = Pool(prep, c)
    ae, hm = mm.ae_model(c, ds.dim, ds.t_his, ds.t_pred), mm.heatmap_model(c)
    x0, y0 = jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, ds.t_pred, ds.dim))
    parents, size = pool.parents, c.hm_size

    def ae_batches(rng):
        j = rng.integers(0, len(pool.windows), c.batch_size)
        m = pool.members(rng, j)
        return {"x": pool.x[j], "y": pool.targets(j, m)}

    # The codebook's cell of every pool window, set when the heatmap stage starts (`hm_init`), before its
    # first training batch; the shape check of the batches before any stage runs draws without it.
    map_cells = {}

    def hm_init(key, frozen):
        map_cells["cells"] = np.asarray(frozen["codebook"]["cells"]) if c.dedupe_members else None
        return hm.init(key, x0)

    def hm_batches(rng):
        j = rng.integers(0, len(pool.windows), c.batch_size)
        members, mask = pool.member_subsets(rng, j, c.max_members, map_cells.get("cells"))
        return {"x": pool.x[j], "members": members, "mask": mask}

    def ft_batches(rng):
        j = rng.integers(0, len(pool.windows), c.batch_size)
        m = pool.members(rng, j)
        return {"x": pool.x[j], "y": pool.targets(j, m), "member": m.astype(np.int32)}

    def hm_loss(p, frozen, batch, key):
        cb = frozen["codebook"]
        b = dict(batch, x=mm.motion_transfer(batch["x"], cb["template"], parents))
        return mm.heatmap_loss(hm, p, cb["cells"], b, size=size, sigma=c.hm_sigma, pos_weight=c.pos_weight)

    def ft_loss(p, frozen, batch, key):
        cb = frozen["codebook"]
        cell = cb["cells"][batch["member"]]
        b = {"x": batch["x"], "y": batch["y"], "cell": cell[:, 0] * size + cell[:, 1]}
        return mm.finetune_loss(ae, p, cb["table"].reshape(size * size, -1), b, scale=c.loss_scale)

    return [
        Stage(
            name="autoencoder", init=lambda key, _f: ae.init(key, x0, y0), optimizer=_adam(c, c.ae_steps),
            loss=lambda p, _f, batch, key: mm.ae_loss(ae, p, batch, scale=c.loss_scale), batches=ae_batches,
            num_steps=c.ae_steps, init_seed=cfg.seed, data_seed=cfg.seed,
        ),
        Stage(
            name="codebook", init=lambda key, f: _codebook(ae, f["autoencoder"], pool, c, cfg.seed),
            optimizer=optax.set_to_zero(), loss=None, batches=None, num_steps=0, frozen=("autoencoder",),
        ),
        Stage(
            name="heatmap", init=hm_init, optimizer=_adam(c, c.hm_steps), loss=hm_loss,
            batches=hm_batches, num_steps=c.hm_steps, init_seed=cfg.seed + 1, data_seed=cfg.seed + 1,
            frozen=("codebook",),
        ),
        Stage(
            name="finetune", init=lambda key, f: jax.tree.map(jnp.array, f["autoencoder"]),
            optimizer=optax.multi_transform(
                {"train": _adam(c, c.ft_steps), "freeze": optax.set_to_zero()}, _finetune_labels
            ),
            loss=ft_loss, batches=ft_batches, num_steps=c.ft_steps, init_seed=cfg.seed + 2, data_seed=cfg.seed + 2,
            frozen=("autoencoder", "codebook"),
        ),
    ]


def modes_fn(cfg, ds, params: dict):
    """Returns a jitted `x (b, t_his, D) -> mm.Modes`: every window's modes, confidences and per-joint uncertainties."""
    c, ae, ae_params = _decoder(cfg, ds, params)
    hm = mm.heatmap_model(c)
    parents = tuple(ds.skeleton.parents)
    hm_params, codebook = params["heatmap"], params["codebook"]
    return jax.jit(
        lambda x: mm.predict_modes(
            ae, ae_params, hm, hm_params, codebook, x, parents, min_distance=c.peak_min_distance,
            threshold_rel=c.peak_threshold_rel, max_peaks=c.max_peaks, scale=c.loss_scale,
        )
    )


def _decoder(cfg, ds, params: dict):
    """Returns `(settings, autoencoder, its parameters)`: the fine-tuned decoder where that stage is trained."""
    c = settings(cfg)
    return c, mm.ae_model(c, ds.dim, ds.t_his, ds.t_pred), params.get("finetune", params["autoencoder"])


def labels(params: dict) -> list[str]:
    """Returns the action labels the codebook's cells carry, in label-index order (the last axis of `label_counts`)."""
    cb = params["codebook"]
    if "label_counts" not in cb:
        raise ValueError(
            "this run's MotionMap codebook has no action labels per cell (computed before they were recorded): "
            "retrain the codebook stage, and the heatmap and finetune stages trained on its map (delete the work "
            "directory's codebook/, heatmap/ and finetune/ folders, then `jaxmotion train --resume` keeps the "
            "autoencoder), or add the labels to the loaded parameters without a new map: "
            "params = jaxmotion.methods.motionmap.with_labels(cfg, prep, params)"
        )
    return _decode_names(cb["label_names"])


def with_labels(cfg, prep, params: dict) -> dict:
    """Returns `params` whose codebook carries the label counts per cell, computed from its stored cells (no new t-SNE).

    For a codebook computed before label counts were recorded; `prep` must hold the training data it
    was computed from (the same training windows, `MotionMapConfig.pool_stride`).
    """
    pool = Pool(prep, settings(cfg))
    cells = np.asarray(params["codebook"]["cells"])
    if len(cells) != len(pool.windows):
        raise ValueError(
            f"with_labels: the codebook holds {len(cells)} training futures but this data gives {len(pool.windows)} "
            "training windows: not the data (or pool_stride) it was computed from"
        )
    size = params["codebook"]["table"].shape[0]
    return {**params, "codebook": {**params["codebook"], **_label_fields(cells, pool.labels, size)}}


def label_modes_fn(cfg, ds, params: dict, action: str):
    """Returns a jitted `x (b, t_his, D) -> mm.Modes`: the modes whose cell's majority label is `action`, by confidence.

    The modes are `modes_fn`'s, restricted with `mm.select_label`: the others become padding, and a
    window whose map has no peak of that action has no valid mode (`modes.valid[b].any()` False).
    Raises a ValueError naming the codebook's labels when `action` is not one of them.
    """
    names = labels(params)
    if action not in names:
        raise ValueError(f"label_modes_fn: {action!r} is not a label of this codebook; its cells carry {names}")
    modes, counts, a = modes_fn(cfg, ds, params), params["codebook"]["label_counts"], names.index(action)
    return jax.jit(lambda x: mm.select_label(modes(x), counts, a))


def near_mode_fn(cfg, ds, params: dict, *, k: int, radius: float):
    """Returns a jitted `(x (b, t_his, D), centre (b, 2) cells, key) -> mm.NearSamples`: K futures near a chosen mode.

    Each future decodes the code of a random cell within `radius` cells of `centre` (a mode's
    cell, `Modes.cells[:, rank]`), with X (`mm.sample_near_mode`).
    """
    if k < 1 or not radius >= 0:
        raise ValueError(f"near_mode_fn: need k >= 1 and radius >= 0 (cells), got k={k}, radius={radius}")
    c, ae, ae_params = _decoder(cfg, ds, params)
    table = params["codebook"]["table"]
    return jax.jit(
        lambda x, centre, key: mm.sample_near_mode(ae, ae_params, table, x, centre, key, k=k, radius=radius, scale=c.loss_scale)
    )


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity and, once the heatmap is trained,
    MotionMap's top-K modes."""
    out = {"zero_velocity": zero_velocity(ds.t_pred, k)}
    if "heatmap" not in params:
        return out
    modes = modes_fn(cfg, ds, params)
    out["motionmap"] = jax.jit(lambda x, key: mm.select_k(modes(x), k))
    if settings(cfg).k_protocol == "release":  # the same futures at every K: all peaks and zero-velocity
        out["motionmap_all_peaks"] = jax.jit(lambda x, key: mm.all_peaks(modes(x), x))
    return out


def _distinct(cfg, ds, params: dict) -> ExtraMetrics:
    """`Method.extra_metrics`: the number of different futures among a window's samples (ANP + 1 for `motionmap_all_peaks`)."""
    return ExtraMetrics(lambda pred, gt: {"distinct_futures": mm.distinct_futures(pred).astype(np.float64)})


def known_mode_statistics(cfg, prep, params: dict, threshold: float | None = None, batch: int = 64) -> dict:
    """Returns how MotionMap's variable set of modes matches a dataset's known modes (the synthetic data's `known_modes`).

    Test windows whose decision point is at most `cfg.mode_max_boundary` frames away (where the
    modes are distinct) are used. Per window: the number of predicted modes (vs the true number);
    each predicted mode is assigned to its nearest true mode and reaches it when their ADE term is
    below `threshold` (default `cfg.mode_threshold`); a true mode's confidence is the largest among
    the predicted modes that reach it (0 if none). Reported: mode counts, recall over all peaks,
    the per-window Spearman correlation of true-mode confidence with the true mode probabilities
    (windows where it is defined), and the Spearman correlation over the 6 modes of the confidence
    averaged over windows.
    """
    from scipy.stats import spearmanr

    ds = prep.dataset
    if ds.known_modes is None:
        raise ValueError(f"known_mode_statistics: dataset {ds.name!r} does not know its modes")
    km = ds.known_modes(ds)
    keep = prep.keep
    sel = km.boundary[keep] <= cfg.mode_max_boundary
    true_modes, x = km.modes[keep][sel], prep.x[sel]
    probs = np.asarray(km.probs)
    thr = cfg.mode_threshold if threshold is None else threshold
    fn = modes_fn(cfg, ds, params)
    n_pred, conf_true = [], []
    for s in range(0, len(x), batch):
        xb = x[s : s + batch]
        pad = batch - len(xb)
        out = fn(jnp.asarray(np.concatenate([xb, np.repeat(xb[-1:], pad, 0)]) if pad else xb))
        fut, conf, valid = (np.asarray(a)[: len(xb)] for a in (out.futures, out.confidence, out.valid))
        for f, cf, v, tm in zip(fut, conf, valid, true_modes[s : s + batch]):
            f, cf = f[v], cf[v]
            n_pred.append(len(f))
            d = np.linalg.norm(f[:, None] - tm[None], axis=-1).mean(-1)  # (peaks, modes)
            ct = np.zeros(len(tm))
            for i, j in enumerate(d.argmin(1)):
                if d[i, j] < thr:
                    ct[j] = max(ct[j], cf[i])
            conf_true.append(ct)
    n_pred, conf_true = np.asarray(n_pred), np.stack(conf_true)
    rhos = [spearmanr(c, probs).statistic for c in conf_true if np.ptp(c) > 0]
    return {
        "windows": int(len(x)),
        "true_modes_per_window": int(true_modes.shape[1]),
        "predicted_modes_mean": float(n_pred.mean()),
        "predicted_modes_median": float(np.median(n_pred)),
        "predicted_modes_hist": np.bincount(n_pred).tolist(),
        "recall_all_peaks": float((conf_true > 0).mean()),
        "recall_all_peaks_weighted": float(((conf_true > 0) * probs).sum(1).mean() / probs.sum()),
        "spearman_per_window_mean": float(np.mean(rhos)) if rhos else float("nan"),
        "spearman_windows": int(len(rhos)),
        "mean_confidence_per_mode": conf_true.mean(0).tolist(),
        "spearman_mean_confidence": float(spearmanr(conf_true.mean(0), probs).statistic),
    }


def draw_pictures(cfg, prep, params: dict, workdir, i: int = 0) -> list:
    """Writes MotionMap's two pictures for test window `i` and returns their paths (paper Fig. 5 and 6).

    `motionmap_maps.png`: the predicted map with its peaks numbered by rank, beside the ground-truth
    map (Gaussian bumps at the cells of the window's MotionMap multimodal futures among the
    training windows). `motionmap_modes.png`: the decoded modes' end poses ranked by confidence,
    each joint's marker size its predicted uncertainty (sigma) at the last frame.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxmotion.formats.atomic import atomic_path
    from jaxmotion.pictures.viz import draw_pose, frames_to_joints, view_axes

    from pathlib import Path

    ds, c = prep.dataset, settings(cfg)
    workdir = Path(workdir)
    cb = params["codebook"]
    pool = Pool(prep, c)
    x = prep.x[i : i + 1]
    out = modes_fn(cfg, ds, params)(jnp.asarray(x))
    heat, cells, conf, valid = (np.asarray(a)[0] for a in (out.heatmap, out.cells, out.confidence, out.valid))
    f = c.descriptor_frames
    sets = metrics.motionmap_mm_sets(x[:, -f:], pool.thr, pool.parents, reference_desc=pool.x[:, -f:])
    members = np.asarray(sets.idx)[0, np.asarray(sets.mask)[0]]
    gt_cells = np.asarray(cb["cells"])[members].astype(np.float32)
    gt = np.asarray(mm.gaussian_heatmap(jnp.asarray(gt_cells.reshape(-1, 2)), jnp.ones(len(gt_cells), bool), c.hm_size, c.hm_sigma))
    fig, axs = plt.subplots(1, 2, figsize=(10, 5))
    axs[0].imshow(heat, cmap="magma")
    for r, (cell, ok) in enumerate(zip(cells, valid)):
        if ok:
            axs[0].plot(cell[1], cell[0], "c+", ms=10)
            axs[0].text(cell[1] + 1, cell[0] - 1, str(r + 1), color="c", fontsize=8)
    axs[0].set_title(f"predicted map, {int(valid.sum())} peaks (numbered by confidence)", fontsize=9)
    axs[1].imshow(gt, cmap="magma")
    axs[1].set_title(
        f"ground truth: {len(members)} multimodal training futures" if len(members) else
        f"ground truth: empty, no training window within {pool.thr:g} m of this window's last {f} frames", fontsize=9,
    )
    for a in axs:
        a.axis("off")
    paths = [workdir / "motionmap_maps.png"]
    with atomic_path(paths[0]) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)

    n = int(valid.sum())
    fut, sig = np.asarray(out.futures)[0, :n], np.asarray(out.sigma)[0, :n]
    xj, pj = frames_to_joints(x[0]), frames_to_joints(fut)
    up, across, _ = view_axes(xj)
    parents = ds.skeleton.parents
    fig, ax = plt.subplots(figsize=(2 + 1.6 * max(n, 1), 3.5))
    step = 1.3 * np.ptp(xj[..., across]) + 0.5
    draw_pose(ax, xj[-1], parents, across, up, color="0.6", lw=2)
    ax.text(0, xj[-1, :, up].max() + 0.1, "last observed", ha="center", fontsize=8)
    for r in range(n):
        dx = (r + 1) * step
        draw_pose(ax, pj[r, -1], parents, across, up, dx=dx, color=plt.cm.viridis(r / max(n, 1)), lw=2)
        s_last = np.concatenate([[0.0], sig[r, -1]])  # the root has no uncertainty
        ax.scatter(pj[r, -1, :, across] + dx, pj[r, -1, :, up], s=2000 * s_last**2 + 2, alpha=0.3, color="r")
        ax.text(dx, xj[-1, :, up].max() + 0.1, f"#{r + 1} conf {conf[r]:.2f}", ha="center", fontsize=8)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"{ds.name} test window {i}: modes ranked by confidence, end poses; red: sigma per joint", fontsize=9)
    paths.append(workdir / "motionmap_modes.png")
    with atomic_path(paths[1]) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return paths


METHOD = Method(
    name="motionmap",
    config_type=MotionMapConfig,
    stages=stages,
    predictors=predictors,
    reference_futures="train",
    extra_metrics=_distinct,
    pictures=draw_pictures,
    description="MotionMap (Hosseininejad, Shukla et al., CVPR 2025): heatmap over futures, modes ranked by confidence",
)
