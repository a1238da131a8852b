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
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion.data.windows import test_windows
from jaxmotion.method import Method, Stage
from jaxmotion.methods.common import zero_velocity
from jaxmotion.models import motionmap as mm
from jaxmotion.models.motionmap import MotionMapConfig


def settings(cfg) -> MotionMapConfig:
    """Returns the checked `cfg.method_config` (the defaults when it is None)."""
    c = METHOD.settings(cfg)
    if c.descriptor_frames < 1 or c.hm_size < 8 or c.peak_min_distance < 1 or not 0 <= c.peak_threshold_rel < 1:
        raise ValueError(
            f"MotionMapConfig: need descriptor_frames >= 1, hm_size >= 8, peak_min_distance >= 1 and "
            f"0 <= peak_threshold_rel < 1, got {c.descriptor_frames}, {c.hm_size}, {c.peak_min_distance}, {c.peak_threshold_rel}"
        )
    return c


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
        self.windows, _, _ = test_windows(prep.train_frames, ds.t_his, ds.t_pred, step=stride)
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
    def sets(self) -> tuple[np.ndarray, np.ndarray]:
        if self._sets is None:
            s = mm.motionmap_mm_sets(
                self.x[:, -self.c.descriptor_frames :], self.thr, self.parents, cache_dir=self.c.mm_cache_dir
            )
            self._sets = (np.asarray(s.idx), np.asarray(s.mask))
        return self._sets

    def members(self, rng: np.random.Generator, j: np.ndarray) -> np.ndarray:
        """Returns one random multimodal member of each pool window `j`."""
        idx, mask = self.sets
        counts = mask[j].sum(1)
        return idx[j, (rng.random(len(j)) * counts).astype(int)]

    def targets(self, j: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Returns the futures of members `m` motion-transferred onto the skeletons of windows `j`."""
        return np.asarray(self._transfer(jnp.asarray(self.y[m]), jnp.asarray(self.x[j, -1])))

    def member_subsets(self, rng: np.random.Generator, j: np.ndarray, cap: int) -> tuple[np.ndarray, np.ndarray]:
        """Returns `(members (b, cap), mask)`: each window's set, or a random `cap` of it when larger."""
        idx, mask = self.sets
        out, ok = np.zeros((len(j), cap), np.int32), np.zeros((len(j), cap), bool)
        for b, w in enumerate(j):
            s = idx[w, mask[w]]
            if len(s) > cap:
                s = rng.choice(s, cap, replace=False)
            out[b, : len(s)], ok[b, : len(s)] = s, True
        return out, ok


def _adam(c: MotionMapConfig, steps: int):
    # The release uses Adam (amsgrad) with ReduceLROnPlateau; here a cosine decay over the stage's fixed budget.
    return optax.amsgrad(optax.cosine_decay_schedule(c.lr, max(steps, 1), alpha=0.05))


def _codebook(ae: mm.MotionMapAE, ae_params, pool: Pool, c: MotionMapConfig, seed: int) -> dict:
    """Returns the codebook stage's parameters: map table, pool cells and codes, template skeleton."""
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
        "template": jnp.asarray(pool.x[0, -1]), "points": jnp.asarray(pts),
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

    def hm_batches(rng):
        j = rng.integers(0, len(pool.windows), c.batch_size)
        members, mask = pool.member_subsets(rng, j, c.max_members)
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
            name="heatmap", init=lambda key, _f: hm.init(key, x0), optimizer=_adam(c, c.hm_steps), loss=hm_loss,
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
    c = settings(cfg)
    ae, hm = mm.ae_model(c, ds.dim, ds.t_his, ds.t_pred), mm.heatmap_model(c)
    ae_params = params.get("finetune", params["autoencoder"])
    parents = tuple(ds.skeleton.parents)
    return jax.jit(
        lambda x: mm.predict_modes(
            ae, ae_params, hm, params["heatmap"], params["codebook"], x, parents, min_distance=c.peak_min_distance,
            threshold_rel=c.peak_threshold_rel, max_peaks=c.max_peaks, scale=c.loss_scale,
        )
    )


def predictors(cfg, ds, params: dict, k: int) -> dict:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers: zero-velocity and MotionMap's top-K modes."""
    modes = modes_fn(cfg, ds, params)
    return {
        "zero_velocity": zero_velocity(ds.t_pred, k),
        "motionmap": jax.jit(lambda x, key: mm.select_k(modes(x), k)),
    }


METHOD = Method(
    name="motionmap",
    config_type=MotionMapConfig,
    stages=stages,
    predictors=predictors,
    reference_futures="train",
    description="MotionMap (Hosseininejad, Shukla et al., CVPR 2025): heatmap over futures, modes ranked by confidence",
)
