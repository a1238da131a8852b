"""The DLow-family job: data -> CVAE -> DLow Q networks -> evaluation -> report.

Used by the `jaxmotion` command; every step is also callable from Python. Layout of a work
directory:

    workdir/cvae/ckpt, workdir/cvae/log.jsonl       CVAE stage
    workdir/dlow_k{K}/ckpt, .../log.jsonl            one DLow Q network per evaluated K
    workdir/metrics.json                             PROTOCOL sec. 5 records, one per (method, K)
    workdir/samples.png                              observed motion and K predicted futures
"""

from __future__ import annotations

import dataclasses
import functools
import json
import platform
import time
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmotion.config import Config, to_dict
from jaxmotion.data.types import MotionDataset
from jaxmotion.data.windows import TrainSampler, sequence_frames, test_windows
from jaxmotion.models import dlow
from jaxmotion.train.loop import TrainState, create_state, fit, lr_schedule, make_train_step, restore_params

METHODS = ("zero_velocity", "cvae", "dlow")


def load_data(cfg: Config, data: str | None = None) -> MotionDataset:
    """Returns the dataset named by `data` (a path) or else by `cfg.dataset` ("synthetic" or a path)."""
    spec = data or cfg.dataset
    if spec == "synthetic":
        from jaxmotion.data.synthetic import make_synthetic

        return make_synthetic(cfg.seed)
    from jaxmotion.data.datasets import load_dataset

    return load_dataset(spec)


@dataclasses.dataclass
class Prepared:
    """Frame vectors for training and the protocol test windows of one dataset."""

    dataset: MotionDataset
    sampler: TrainSampler
    windows: np.ndarray  # (N, t_total, D)
    seq_index: np.ndarray
    starts: np.ndarray
    keep: np.ndarray  # indices of these windows among all protocol test windows

    @property
    def x(self) -> np.ndarray:
        return self.windows[:, : self.dataset.t_his]

    @property
    def y(self) -> np.ndarray:
        return self.windows[:, self.dataset.t_his :]


def prepare(ds: MotionDataset, max_test_windows: int | None = None) -> Prepared:
    """Returns train sampler and test windows (PROTOCOL sec. 3: test stride t_his, random train starts)."""
    sampler = TrainSampler(sequence_frames(ds.train), ds.t_total)
    windows, seq_index, starts = test_windows(sequence_frames(ds.test), ds.t_his, ds.t_pred)
    keep = np.arange(len(windows))
    if max_test_windows is not None and len(windows) > max_test_windows:
        # Evenly spaced, so a quick evaluation still covers every test sequence.
        keep = np.linspace(0, len(windows) - 1, max_test_windows).round().astype(int)
        windows, seq_index, starts = windows[keep], seq_index[keep], starts[keep]
    return Prepared(ds, sampler, windows, seq_index, starts, keep)


def cvae_model(cfg: Config, ds: MotionDataset) -> dlow.DLowCVAE:
    c = cfg.cvae
    return dlow.DLowCVAE(dim=ds.dim, horizon=ds.t_pred, nz=c.nz, nh_rnn=c.nh_rnn, nh_mlp=tuple(c.nh_mlp))


def q_model(cfg: Config, nk: int) -> dlow.DLowQ:
    d = cfg.dlow
    return dlow.DLowQ(nz=cfg.cvae.nz, nk=nk, nh_rnn=d.nh_rnn, nh_mlp=tuple(d.nh_mlp))


def _cvae_state(cfg: Config, ds: MotionDataset):
    model = cvae_model(cfg, ds)
    x = jnp.zeros((1, ds.t_his, ds.dim))
    y = jnp.zeros((1, ds.t_pred, ds.dim))
    params = model.init(jax.random.key(cfg.seed), x, y, jax.random.key(0))
    c = cfg.cvae
    tx = optax.adam(lr_schedule(c.lr, c.num_steps, c.lr_fix_fraction))
    return model, tx, create_state(params, tx)


def _q_state(cfg: Config, ds: MotionDataset, nk: int, cvae_params):
    model = q_model(cfg, nk)
    params = model.init(jax.random.key(cfg.seed + 1), jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, cfg.cvae.nz)))
    d = cfg.dlow
    tx = optax.adam(lr_schedule(d.lr, d.num_steps, d.lr_fix_fraction))
    return model, tx, create_state(params, tx, frozen=cvae_params)


def train_cvae(cfg: Config, prep: Prepared, workdir: Path, resume: bool = False):
    """Returns the trained CVAE parameters (DLow's first stage)."""
    ds = prep.dataset
    model, tx, state = _cvae_state(cfg, ds)
    c = cfg.cvae
    loss = functools.partial(dlow.cvae_loss, model, t_his=ds.t_his, beta=c.beta, lambda_v=c.lambda_v)
    step = make_train_step(lambda p, _frozen, b, k: loss(p, b, k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, c.batch_size), num_steps=c.num_steps,
        workdir=workdir / "cvae", seed=cfg.seed, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc="cvae",
    )
    return state.params


def train_dlow(cfg: Config, prep: Prepared, cvae_params, nk: int, workdir: Path, resume: bool = False):
    """Returns the trained Q-network parameters for `nk` samples, on the frozen CVAE decoder."""
    ds = prep.dataset
    cvae = cvae_model(cfg, ds)
    q, tx, state = _q_state(cfg, ds, nk, cvae_params)
    d = cfg.dlow
    loss = functools.partial(
        dlow.dlow_loss, q, cvae=cvae, t_his=ds.t_his, d_scale=d.d_scale,
        lambda_j=d.lambda_j, lambda_recon=d.lambda_recon, lambda_kl=d.lambda_kl,
    )
    step = make_train_step(lambda p, frozen, b, k: loss(p, cvae_params=frozen, batch=b, key=k), tx)
    state = fit(
        state, step, lambda rng: prep.sampler.sample(rng, d.batch_size), num_steps=d.num_steps,
        workdir=workdir / f"dlow_k{nk}", seed=cfg.seed + nk, resume=resume, ckpt_every=cfg.ckpt_every,
        log_every=cfg.log_every, desc=f"dlow K={nk}",
    )
    return state.params


def train_all(cfg: Config, prep: Prepared, workdir: Path, resume: bool = False) -> dict:
    """Returns `{"cvae": params, "dlow": {K: params}}` after training every stage of the config."""
    cvae_params = train_cvae(cfg, prep, workdir, resume)
    qs = {k: train_dlow(cfg, prep, cvae_params, k, workdir, resume) for k in cfg.eval_k}
    return {"cvae": cvae_params, "dlow": qs}


def restore_all(cfg: Config, prep: Prepared, workdir: Path) -> dict:
    """Returns the parameters saved by `train_all` in `workdir`."""
    ds = prep.dataset
    _, _, state = _cvae_state(cfg, ds)
    cvae_params = restore_params(workdir / "cvae", state).params
    qs = {}
    for k in cfg.eval_k:
        _, _, qstate = _q_state(cfg, ds, k, cvae_params)
        qs[k] = restore_params(workdir / f"dlow_k{k}", qstate).params
    return {"cvae": cvae_params, "dlow": qs}


Predictor = Callable[[jax.Array, jax.Array], jax.Array]  # (x (b, t_his, d), key) -> (b, K, t_pred, d)


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int) -> dict[str, Predictor]:
    """Returns jitted `(x, key) -> (b, K, t_pred, D)` samplers for zero-velocity, CVAE and DLow."""
    cvae = cvae_model(cfg, ds)
    out = {
        "zero_velocity": jax.jit(lambda x, key: jnp.broadcast_to(x[:, None, -1:], (x.shape[0], k, ds.t_pred, x.shape[-1]))),
        "cvae": jax.jit(lambda x, key: dlow.sample_prior(cvae, params["cvae"], x, key, k)),
    }
    if k in params["dlow"]:
        q = q_model(cfg, k)
        out["dlow"] = jax.jit(lambda x, key: dlow.sample_dlow(cvae, params["cvae"], q, params["dlow"][k], x, key))
    return out


def predict_chunks(fn: Predictor, x: np.ndarray, key: jax.Array, batch: int):
    """Yields `(b, K, t_pred, D)` numpy predictions over `x` in fixed-size (padded) batches."""
    n = x.shape[0]
    for i, s in enumerate(range(0, n, batch)):
        xb = x[s : s + batch]
        c = xb.shape[0]
        if c < batch:
            xb = np.concatenate([xb, np.repeat(xb[-1:], batch - c, axis=0)])
        yield np.asarray(fn(jnp.asarray(xb), jax.random.fold_in(key, i)))[:c]


def evaluate(cfg: Config, prep: Prepared, params: dict, workdir: Path, data_label: str | None = None) -> list[dict]:
    """Returns and writes (`workdir/metrics.json`) one PROTOCOL sec. 5 record per (method, K)."""
    from jaxmotion import metrics

    ds = prep.dataset
    modes = None
    if ds.name == "synthetic":
        from jaxmotion.data.synthetic import test_modes

        modes = test_modes(ds)
        sel = prep.keep
        modes = modes._replace(modes=modes.modes[sel], true_mode=modes.true_mode[sel], boundary=modes.boundary[sel])
    x, y = prep.x, prep.y
    mm_sets = metrics.multimodal_gt(x[:, -1], ds.mm_threshold)
    records = []
    for k in cfg.eval_k:
        for name, fn in predictors(cfg, ds, params, k).items():
            t0 = time.perf_counter()
            recalls = []

            def chunks():
                for i, p in enumerate(predict_chunks(fn, x, jax.random.key(cfg.seed + 7), cfg.eval_batch)):
                    if modes is not None:
                        sl = slice(i * cfg.eval_batch, i * cfg.eval_batch + p.shape[0])
                        n, P = p.shape[0], modes.modes.shape[1]
                        r, w = metrics.mode_recall(
                            p, modes.modes[sl], np.broadcast_to(modes.probs, (n, P)), np.ones((n, P), bool), cfg.mode_threshold
                        )
                        recalls.append((np.asarray(r), np.asarray(w)))
                    yield p

            m = metrics.evaluate_windows(chunks(), y, mm_sets, mm_deviation=cfg.mm_deviation)
            if modes is not None:
                sel = modes.boundary <= cfg.mode_max_boundary
                r = np.concatenate([a for a, _ in recalls])[sel]
                w = np.concatenate([b for _, b in recalls])[sel]
                m["mode_recall"] = float(r.mean())
                m["mode_recall_weighted"] = float(w.mean())
                m["mode_threshold"] = cfg.mode_threshold
                m["mode_windows"] = int(sel.sum())
            wall = time.perf_counter() - t0
            rec = {
                "dataset": data_label or ds.name,
                "method": name,
                "K": k,
                "n_windows": int(len(x)),
                "metrics": m,
                "seed": cfg.seed,
                "config": to_dict(cfg),
                "jax_version": jax.__version__,
                "device": f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind} ({platform.machine()})",
                "wall_s": round(wall, 3),
            }
            records.append(rec)
            print(format_record(rec), flush=True)
    workdir.mkdir(parents=True, exist_ok=True)
    with open(workdir / "metrics.json", "w") as f:
        json.dump(records, f, indent=1, default=float)
    return records


def format_record(rec: dict) -> str:
    m = rec["metrics"]
    keys = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "mode_recall", "mode_recall_weighted"]
    vals = " ".join(f"{k}={m[k]:.4f}" for k in keys if k in m)
    return f"[{rec['dataset']}] {rec['method']:<13s} K={rec['K']:<3d} {vals} ({rec['wall_s']:.1f}s)"


def report(cfg: Config, prep: Prepared, params: dict, workdir: Path, method: str = "dlow") -> Path:
    """Writes `workdir/samples.png` for the test window with the largest multimodal ground-truth set."""
    from jaxmotion import metrics
    from jaxmotion.viz import plot_futures

    ds = prep.dataset
    k = max(cfg.eval_k)
    sets = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold)
    i = int(np.argmax(np.asarray(sets.mask).sum(axis=1)))
    fn = predictors(cfg, ds, params, k)[method]
    preds = np.asarray(fn(jnp.asarray(prep.x[i : i + 1]), jax.random.key(cfg.seed + 11)))[0]
    title = (
        f"{ds.name}: test window {i} (sequence {prep.seq_index[i]}, start frame {prep.starts[i]}), "
        f"{method}, K={k}, {ds.t_his} observed -> {ds.t_pred} predicted frames at {ds.fps:g} fps"
    )
    return plot_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, workdir / "samples.png", title=title)
