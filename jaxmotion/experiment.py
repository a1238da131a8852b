"""The job behind the `jaxmotion` command: data -> train a method -> protocol evaluation -> report.

Every step is also callable from Python. A work directory holds one folder per training stage
(`cvae/`, `dlow_k50/`, ... each with `ckpt/`, `log.jsonl` and `stage.json`), `metrics.json`
(PROTOCOL sec. 5 records, one per (predictor, K)), `samples.png` and `samples.gif` (observed motion
and K predicted futures, still and animated) and `predictor.json` (what `jaxmotion.load` needs to
predict from the run alone). The method is looked up in the registry (`jaxmotion.method`) and its stages
are run by the one stage runner (`jaxmotion.train.runner`).
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxmotion import action_metrics, distributed, metrics
from jaxmotion.compile_time import CompileTimer
from jaxmotion.config import Config, to_dict
from jaxmotion.data.datasets import BANDAI_TARBALL, load_dataset
from jaxmotion.data.validation import validation_split
from jaxmotion.data.folder_split import folder_split
from jaxmotion.data.synthetic import make_synthetic
from jaxmotion.data.types import MotionDataset
from jaxmotion.data.windows import SAMPLER_WEIGHTINGS, TrainSampler, canonicalise_windows, split_frames, test_windows
from jaxmotion.errors import DataError
from jaxmotion.formats.atomic import write_text_atomic
from jaxmotion.method import Method, Predictor
from jaxmotion.methods import get_method
from jaxmotion.train import runner

__all__ = ["get_method", "resolve", "load_data", "Prepared", "prepare", "train", "restore", "predictors", "evaluate",
           "report", "Predictor"]


def resolve(cfg: Config) -> Config:
    """Returns `cfg` with its method's settings checked and filled in (`method_config=None` -> the method's defaults)."""
    return dataclasses.replace(cfg, method_config=get_method(cfg.method).settings(cfg))


def load_data(cfg: Config, data: str | None = None, test_files: list[str] | None = None) -> MotionDataset:
    """Returns the dataset of `_load_split` with `cfg.split` applied ("val": `validation_split`, the test split dropped)."""
    ds = _load_split(cfg, data, test_files)
    return validation_split(ds) if cfg.split == "val" else ds


def _load_split(cfg: Config, data: str | None, test_files: list[str] | None) -> MotionDataset:
    """Returns the dataset named by `data` (a path) or else by `cfg.dataset` ("synthetic" or a path).

    `cfg.data_options` go to the loader (e.g. `{"markers": "bandai"}`: Bandai-Namco-2 as markers).
    A plain folder of BVH clips (no dataset protocol) is split by `data.folder_split.folder_split`:
    by subject where the file names carry one, else the last 20% of files are test; `test_files`
    (glob patterns, `--test-files`) choose the test files. `info["split"]` says which way.
    """
    spec = data or cfg.dataset
    if spec == "synthetic":
        if cfg.data_options or test_files:
            raise ValueError(f"the synthetic dataset takes no data_options or test files, got {sorted(cfg.data_options)} {test_files or ''}")
        return make_synthetic(cfg.seed)
    path = Path(spec).expanduser()
    options = dict(cfg.data_options)
    if plain_bvh_folder(path) and "split" not in options:
        split, how = folder_split(path, test_files)
        ds = load_dataset(spec, split=lambda f: split.get(f, "test"), **options)
        ds.info["split"] = how
        return ds
    if test_files:
        raise ValueError(f"--test-files applies to a plain folder of BVH clips; {spec} has its own protocol split")
    return load_dataset(spec, **options)


def plain_bvh_folder(path: Path) -> bool:
    """Returns whether `path` is a folder of BVH files that no dataset protocol (Bandai-Namco-2) claims."""
    if not path.is_dir() or (path / BANDAI_TARBALL).is_file() or any(path.glob("dataset-2_*.bvh")):
        return False
    return any(path.rglob("*.bvh"))


@dataclasses.dataclass
class Prepared:
    """Frame vectors for training and the protocol test windows of one dataset."""

    dataset: MotionDataset
    sampler: TrainSampler | None  # None for a test-only preparation (`prepare(test_only=True)`)
    windows: np.ndarray  # (N, t_total, D)
    seq_index: np.ndarray
    starts: np.ndarray
    keep: np.ndarray  # indices of these windows among all protocol test windows
    train_frames: list[np.ndarray] | None = None  # the training split's frame vectors (uncanonicalised)

    @property
    def x(self) -> np.ndarray:
        return self.windows[:, : self.dataset.t_his]

    @property
    def y(self) -> np.ndarray:
        return self.windows[:, self.dataset.t_his :]


def prepare(ds: MotionDataset, max_test_windows: int | None = None, train_sampler: str = "windows", test_only: bool = False) -> Prepared:
    """Returns train sampler and test windows (PROTOCOL sec. 3: test stride t_his, random train starts).

    `train_sampler` weights the training windows (`TrainSampler`): "windows" (each equally likely)
    or "sequences" (DLow's release: a sequence uniformly, then a start). `test_only`: no training
    windows are needed (the sampler is None), e.g. to evaluate a trained model on a new folder.

    Marker datasets' windows are canonicalised at their first frame (PROTOCOL sec. 4).
    """
    train, train_canon = split_frames(ds, "train")
    test, test_canon = split_frames(ds, "test")
    check_lengths(ds, train, test, train_sampler, test_only)
    sampler = None if test_only else TrainSampler(train, ds.t_total, train_canon, weighting=train_sampler)
    windows, seq_index, starts = test_windows(test, ds.t_his, ds.t_pred)
    if test_canon is not None:
        windows = canonicalise_windows(windows, np.stack([test_canon[i][s] for i, s in zip(seq_index, starts)]))
    keep = np.arange(len(windows))
    if max_test_windows is not None and len(windows) > max_test_windows:
        # Evenly spaced, so a quick evaluation still covers every test sequence.
        keep = np.linspace(0, len(windows) - 1, max_test_windows).round().astype(int)
        windows, seq_index, starts = windows[keep], seq_index[keep], starts[keep]
    return Prepared(ds, sampler, windows, seq_index, starts, keep, train if train_canon is None else None)


def check_lengths(
    ds: MotionDataset, train: list[np.ndarray], test: list[np.ndarray], train_sampler: str = "windows", test_only: bool = False
) -> None:
    """Raises `DataError` saying how many sequences there are, how long the longest is and what the protocol needs,
    when no training window (unless `test_only`) or no test window fits (PROTOCOL sec. 3: test windows need T > t_total)."""
    if train_sampler not in SAMPLER_WEIGHTINGS:
        return  # TrainSampler names the choices
    need = ds.t_total + (1 if train_sampler == "sequences" else 0)
    if (test_only or any(len(f) >= need for f in train)) and any(len(f) > ds.t_total for f in test):
        return
    longest = lambda fs: max((len(f) for f in fs), default=0)  # noqa: E731
    which = "training" if not test_only and not any(len(f) >= need for f in train) else "test"
    hint = ""
    if "split" in ds.info:
        hint = f" Split: {ds.info['split']}. Choose other test files with --test-files, or train at a lower frame rate (data_options={{'fps': 30}}) or with shorter windows (data_options t_his / t_pred)."
    raise DataError(
        ds.info.get("source", ds.name),
        f"no {which} window fits: {len(ds.train)} training sequences (longest {longest(train)} frames) and "
        f"{len(ds.test)} test sequences (longest {longest(test)} frames); the protocol needs "
        f"t_his + t_pred = {ds.t_his} + {ds.t_pred} = {ds.t_total} frames at {ds.fps:g} fps "
        f"({'a test sequence longer than that' if which == 'test' else f'a training sequence of at least {need}'}).{hint}",
    )


def train(cfg: Config, prep: Prepared, workdir: str | Path, resume: bool = False) -> dict:
    """Returns `{stage name: parameters}` after training every stage of the config's method (`runner.train`).

    Writes `workdir/predictor.json` first (`jaxmotion.predictor`): what `jaxmotion.load` needs to predict.
    """
    from jaxmotion.predictor import write_manifest

    if distributed.is_main():
        write_manifest(resolve(cfg), prep.dataset, workdir)
    curve = learning_curve(cfg, prep) if cfg.curve_every > 0 else None
    return runner.train(get_method(cfg.method), cfg, prep, workdir, resume=resume, curve=curve)


CURVE_METRICS = ("APD", "ADE", "FDE", "MMADE", "MMFDE")


def learning_curve(cfg: Config, prep: Prepared) -> runner.Curve:
    """Returns `curve(params) -> {"K", "n_windows", "predictors": {name: {APD, ADE, FDE, MMADE, MMFDE}}} | None`.

    The windows are `cfg.curve_windows` evenly spaced test windows (the same at every point); their
    MM sets come from the evaluation's source (`mm_source`: `cfg.mm_ground_truth`, else the
    method's own) built over every window of that source (`mm_deviation` not applied), so the
    multimodal terms are the full evaluation's for those windows. The predictors are the method's
    for the stages trained so far, less `Method.curve_skip`; None when that leaves none (a stage
    whose later stages are needed to predict). The noise key is the same at every point.
    """
    method, ds = get_method(cfg.method), prep.dataset
    n = len(prep.windows)
    sub = np.unique(np.linspace(0, n - 1, min(cfg.curve_windows, n)).round().astype(int))
    r = mm_reference(prep, mm_source(cfg, method))
    sets = metrics.MMSets(np.asarray(r.sets.idx)[sub], np.asarray(r.sets.mask)[sub])
    ref = prep.y if r.futures is None else r.futures
    transfer = {}
    if r.transfer_parents is not None:  # MotionMap's sources: members transferred onto each window's skeleton
        transfer = dict(transfer_poses=r.transfer_poses[sub], transfer_parents=r.transfer_parents)
    x, y = prep.x[sub], prep.y[sub]

    def curve(params: dict) -> dict | None:
        try:
            fns = method.predictors(cfg, ds, params, cfg.curve_k)
        except KeyError:  # a stage that cannot predict before the later ones are trained
            return None
        out = {}
        for name, fn in fns.items():
            if name in method.curve_skip:
                continue
            chunks = predict_chunks(fn, x, jax.random.key(cfg.seed + 11), cfg.eval_batch)
            m = metrics.evaluate_windows(chunks, y, sets, reference_futures=ref, **transfer)
            out[name] = {k: round(float(m[k]), 6) for k in CURVE_METRICS}
        return {"K": cfg.curve_k, "n_windows": int(len(sub)), "predictors": out} if out else None

    return curve


def restore(cfg: Config, prep: Prepared, workdir: str | Path) -> dict:
    """Returns `{stage name: parameters}` of a trained work directory (`runner.restore`)."""
    return runner.restore(get_method(cfg.method), cfg, prep, workdir)


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int) -> dict[str, Predictor]:
    """Returns the method's jitted K-future predictors by name."""
    return get_method(cfg.method).predictors(cfg, ds, params, k)


# The sources of MMADE / MMFDE's multimodal ground truth (`Config.mm_ground_truth`).
MM_SOURCES = ("test", "train", "motionmap-test", "motionmap-train")
# MotionMap's descriptor: the last three observed frames (paper appendix A; PROTOCOL sec. 2 option).
MOTIONMAP_DESCRIPTOR_FRAMES = 3


class MMReference(NamedTuple):
    """The multimodal ground truth of an evaluation: sets, the futures they index and how they are compared."""

    source: str  # one of MM_SOURCES
    sets: metrics.MMSets
    futures: np.ndarray | None  # the futures `sets` index; None: the test windows' own ground truth
    transfer_poses: np.ndarray | None  # MotionMap: each test window's last observed pose (its skeleton)
    transfer_parents: tuple[int, ...] | None  # MotionMap: the skeleton's parents (root first)


def mm_source(cfg: Config, method: Method) -> str:
    """Returns where `cfg`'s evaluation takes its MM ground truth from: `cfg.mm_ground_truth`, else the method's own."""
    return cfg.mm_ground_truth or method.reference_futures


def mm_reference(prep: Prepared, source: str, *, cache_dir: str | Path | None = None) -> MMReference:
    """Returns the multimodal ground truth of the test windows of `prep` from `source` (one of `MM_SOURCES`).

    "test" (PROTOCOL sec. 2): MM sets over the test windows. "train": the futures of training
    windows (every `t_his` frames of every training sequence) whose last observed pose is within the
    dataset's threshold, a pseudo ground truth some published code compares against.
    "motionmap-test" / "motionmap-train": MotionMap's (PROTOCOL sec. 2 option): the descriptor is
    the last three observed frames, a candidate (a test / training window) is a member when its
    descriptor, motion-transferred onto this window's skeleton (its last observed frame), is within
    the threshold of this window's, and the members' futures are motion-transferred onto that
    skeleton before MMADE / MMFDE. The threshold is the dataset's `mm_threshold` in every case.
    """
    if source not in MM_SOURCES:
        raise ValueError(f"MM ground truth: source must be one of {MM_SOURCES}, got {source!r}")
    ds = prep.dataset
    train = source.endswith("train")
    if train:
        if prep.train_frames is None:
            raise ValueError(f"MM ground truth {source!r}: training-window reference futures need uncanonicalised frames")
        ref, _, _ = test_windows(prep.train_frames, ds.t_his, ds.t_pred)
    if not source.startswith("motionmap"):
        if not train:
            return MMReference(source, metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold), None, None, None)
        sets = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold, reference_last_poses=ref[:, ds.t_his - 1])
        return MMReference(source, sets, ref[:, ds.t_his :], None, None)
    if prep.train_frames is None:
        raise ValueError(f"MM ground truth {source!r}: motion transfer needs joint frames, not marker frames")
    parents = tuple(int(q) for q in ds.skeleton.parents)
    f = min(MOTIONMAP_DESCRIPTOR_FRAMES, ds.t_his)
    ref_desc = ref[:, ds.t_his - f : ds.t_his] if train else None
    sets = metrics.motionmap_mm_sets(prep.x[:, -f:], ds.mm_threshold, parents, reference_desc=ref_desc, cache_dir=cache_dir)
    futures = ref[:, ds.t_his :] if train else None
    return MMReference(source, sets, futures, np.asarray(prep.x[:, -1], np.float32), parents)


def reference_sets(method: Method, prep: Prepared):
    """Returns `(mm, reference_futures)` for `metrics.evaluate_windows`: the multimodal ground truth the method asks for.

    "test" (PROTOCOL sec. 2) or "train" (`Method.reference_futures`); see `mm_reference`.
    """
    r = mm_reference(prep, method.reference_futures)
    return r.sets, r.futures


def skip_single_future(prep: Prepared, method: Method, source: str | None = None) -> Prepared:
    """Returns `prep` without the test windows whose MM set is themselves alone (`Config.mm_deviation="gsps"`).

    GSPS's release (`eval.py`: `if gt_multi.shape[0] == 1: continue`) skips such a window in every
    metric and averages over the others. MM membership is symmetric (PROTOCOL sec. 2), so no
    remaining window loses a member: the protocol on the remaining windows is that deviation.
    """
    source = source or method.reference_futures
    if source != "test":
        raise ValueError(f"mm_deviation='gsps' needs test-window reference futures; the MM ground truth of {method.name!r} here is {source!r}")
    sets = metrics.multimodal_gt(prep.x[:, -1], prep.dataset.mm_threshold)
    idx, mask = np.asarray(sets.idx), np.asarray(sets.mask)
    sel = np.flatnonzero((mask & (idx != np.arange(len(idx))[:, None])).any(axis=1))
    if len(sel) == 0:
        raise ValueError(f"mm_deviation='gsps': none of the {len(idx)} test windows has another window within the MM threshold")
    return dataclasses.replace(prep, windows=prep.windows[sel], seq_index=prep.seq_index[sel], starts=prep.starts[sel],
                               keep=prep.keep[sel])


def predict_chunks(fn: Predictor, x: np.ndarray, key: jax.Array, batch: int, *, mesh: Mesh | None = None):
    """Yields `(b, K, t_pred, D)` numpy predictions over `x` in fixed-size (padded) batches of `batch` windows.

    Each batch is split over the devices of `mesh` (default `distributed.data_mesh()`: every device
    of every process), each predicting its share of the windows; a batch is padded to a multiple of
    the device count. With several processes every one calls this alike and receives every prediction.
    """
    mesh = distributed.data_mesh() if mesh is None else mesh
    sharding = NamedSharding(mesh, PartitionSpec("data"))
    size = -(-batch // mesh.size) * mesh.size
    n = x.shape[0]
    for i, s in enumerate(range(0, n, batch)):
        xb = x[s : s + batch]
        c = xb.shape[0]
        if c < size:
            xb = np.concatenate([xb, np.repeat(xb[-1:], size - c, axis=0)])
        out = fn(distributed.global_batch(xb, sharding), jax.random.fold_in(key, i))
        yield distributed.gather(out)[:c]


def action_evaluator(cfg: Config, prep: Prepared) -> action_metrics.ActionEvaluator | None:
    """Returns the CMD / FID evaluator of `prep`'s test windows (`prepare`'s result), or None without labels.

    The classifier is trained once per dataset at `cfg.action_classifier_steps` and cached
    (`jaxmotion.action_metrics`); its feature batches follow `cfg.eval_batch`.
    """
    c = action_metrics.ClassifierConfig(num_steps=cfg.action_classifier_steps)
    return action_metrics.evaluator(prep.dataset, prep.y, prep.seq_index, prep.starts, config=c, batch=cfg.eval_batch)


def evaluate(
    cfg: Config, prep: Prepared, params, workdir: Path, data_label: str | None = None, manifest: bool = True
) -> list[dict]:
    """Returns and writes (`workdir/metrics.json`) one PROTOCOL sec. 5 record per (predictor, K).

    Mode recall is added where the dataset knows its test windows' futures (`MotionDataset.known_modes`),
    and the method's `extra_metrics` where it has them. `manifest`: write `predictor.json` when the
    work directory has none (False when `workdir` holds the evaluation of a model trained elsewhere).
    """
    ds = prep.dataset
    method = get_method(cfg.method)
    cfg = resolve(cfg)
    deviation = cfg.mm_deviation
    source = mm_source(cfg, method)
    if deviation == "gsps":  # GSPS's release: windows whose MM set is themselves alone enter no metric
        prep, deviation = skip_single_future(prep, method, source), None
    modes = None
    if ds.known_modes is not None:
        modes = ds.known_modes(ds)
        sel = prep.keep
        modes = modes._replace(modes=modes.modes[sel], true_mode=modes.true_mode[sel], boundary=modes.boundary[sel])
    x, y = prep.x, prep.y
    transfer = {}
    if cfg.mm_deviation == "divsamp":
        # DivSamp's deviation drops exact-duplicate last poses, so evaluate_windows builds its sets from the poses.
        if source != "test":
            raise ValueError(f"mm_deviation='divsamp' needs test-window reference futures; the MM ground truth here is {source!r}")
        mm, thr, ref_futures = x[:, -1], ds.mm_threshold, None
    else:
        ref = mm_reference(prep, source)
        mm, thr, ref_futures = ref.sets, None, ref.futures
        if ref.transfer_parents is not None:
            transfer = dict(transfer_poses=ref.transfer_poses, transfer_parents=ref.transfer_parents)
    if manifest and not (workdir / "predictor.json").exists():  # a run trained before `predictor.json` existed
        from jaxmotion.predictor import write_manifest

        write_manifest(cfg, ds, workdir)
    records = []
    extra_fn, record_fields = method.evaluation_hooks(cfg, ds, params)
    action = action_evaluator(cfg, prep) if cfg.action_metrics else None
    if action is not None:
        record_fields = {**record_fields, "action_classifier": action.summary()}
    for k in cfg.eval_k:
        for name, fn in method.predictors(cfg, ds, params, k).items():
            t0 = time.perf_counter()
            recalls, extras, action_parts = [], [], []
            # K copies of one future: scored on one copy, every metric unchanged (`Method.deterministic`).
            copies = k if name in method.deterministic else 1

            def chunks():
                for i, p in enumerate(predict_chunks(fn, x, jax.random.key(cfg.seed + 7), cfg.eval_batch)):
                    if copies > 1:
                        p = p[:, :1]
                    if modes is not None:
                        sl = slice(i * cfg.eval_batch, i * cfg.eval_batch + p.shape[0])
                        n, P = p.shape[0], modes.modes.shape[1]
                        # The last batch is padded to the others' size so that mode_recall compiles once.
                        fill = lambda a: np.concatenate([a, np.repeat(a[-1:], cfg.eval_batch - n, axis=0)])  # noqa: E731
                        b = cfg.eval_batch
                        r, w = metrics.mode_recall(
                            fill(p), fill(modes.modes[sl]), np.broadcast_to(modes.probs, (b, P)), np.ones((b, P), bool),
                            cfg.mode_threshold,
                        )
                        recalls.append((np.asarray(r)[:n], np.asarray(w)[:n]))
                    if extra_fn is not None:
                        extras.append(extra_fn(ds, p, y[i * cfg.eval_batch : i * cfg.eval_batch + p.shape[0]]))
                    if action is not None:
                        action_parts.append(action.chunk(p, copies))
                    yield p

            with CompileTimer() as compiling:  # the predictor's first call, and the metrics' at a new K, compile
                m = metrics.evaluate_windows(
                    chunks(), y, mm, thr=thr, reference_futures=ref_futures, mm_deviation=deviation, **transfer
                )
            m.pop("n_windows")  # a top-level field of the record (PROTOCOL sec. 5)
            if modes is not None:
                sel = modes.boundary <= cfg.mode_max_boundary
                r = np.concatenate([a for a, _ in recalls])[sel]
                w = np.concatenate([b for _, b in recalls])[sel]
                m["mode_recall"] = float(r.mean())
                m["mode_recall_weighted"] = float(w.mean())
                m["mode_threshold"] = cfg.mode_threshold
                m["mode_windows"] = int(sel.sum())
            for key in extras[0] if extras else ():
                m[key] = float(np.nanmean(np.concatenate([e[key] for e in extras])))
            if action is not None:
                m.update(action.result(action_parts))
            wall = time.perf_counter() - t0
            rec = {
                "dataset": data_label or ds.name,
                "method": name,
                "K": k,
                "n_windows": int(len(x)),
                "metrics": m,
                "mm_source": source,  # where MMADE / MMFDE's ground truth came from (`mm_reference`)
                "seed": cfg.seed,
                "config": {**to_dict(cfg), **record_fields},
                "jax_version": jax.__version__,
                "device": f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind} ({platform.machine()})",
                "wall_s": round(wall, 3),
                "compile_s": round(compiling.seconds, 3),  # part of wall_s: tracing + XLA compilation
            }
            records.append(rec)
            print(format_record(rec), flush=True)
    workdir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(workdir / "metrics.json", json.dumps(records, indent=1, default=float))
    return records


def format_record(rec: dict) -> str:
    m = rec["metrics"]
    keys = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "mode_recall", "mode_recall_weighted", "CMD", "FID"]
    vals = " ".join(f"{k}={m[k]:.4f}" for k in keys if k in m)
    compiling = f", {rec['compile_s']:.1f}s compiling" if "compile_s" in rec else ""
    return f"[{rec['dataset']}] {rec['method']:<13s} K={rec['K']:<3d} {vals} ({rec['wall_s']:.1f}s{compiling})"


def most_multimodal(prep: Prepared, n: int) -> np.ndarray:
    """Returns the indices of the `n` test windows whose multimodal ground truth is most spread, most spread first.

    The spread of window i is the mean distance of its MM futures' end poses (PROTOCOL sec. 2 sets)
    from its own true end pose: where a good stochastic predictor should show several distinct futures.
    """
    idx, mask = metrics.multimodal_gt(prep.x[:, -1], prep.dataset.mm_threshold)
    idx, mask = np.asarray(idx), np.asarray(mask)
    ends = prep.y[:, -1]
    spread = (np.linalg.norm(ends[idx] - ends[:, None], axis=-1) * mask).sum(1) / mask.sum(1)
    return np.argsort(-spread, kind="stable")[:n]


def report(cfg: Config, prep: Prepared, params, workdir: Path, method: str | None = None) -> Path:
    """Writes `workdir/samples.png` and `samples.gif` (animated) for the test window whose ground truth is most multimodal.

    That is the window whose multimodal ground-truth futures (PROTOCOL sec. 2) end furthest apart
    on average: where a good stochastic predictor should show several distinct futures. A method
    with `Method.pictures` draws its own pictures of that window too; their paths are printed.
    """
    from jaxmotion.viz import plot_futures  # matplotlib: imported only when a picture is drawn

    ds = prep.dataset
    k = max(cfg.eval_k)
    i = int(most_multimodal(prep, 1)[0])
    fns = predictors(cfg, ds, params, k)
    method = method or _main_predictor(cfg, fns)
    fn = fns[method]
    preds = np.asarray(fn(jnp.asarray(prep.x[i : i + 1]), jax.random.key(cfg.seed + 11)))[0]
    title = (
        f"{ds.name}: test window {i} (sequence {prep.seq_index[i]}, start frame {prep.starts[i]}), "
        f"{method}, K={k}, {ds.t_his} observed -> {ds.t_pred} predicted frames at {ds.fps:g} fps"
    )
    png = plot_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, workdir / "samples.png", title=title)
    from jaxmotion.animate import animate_futures

    animate_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, workdir / "samples.gif", fps=ds.fps,
                    title=f"{ds.name}: test window {i}, {method}, K={k}; observed, then the futures")
    pictures = get_method(cfg.method).pictures
    for path in pictures(cfg, prep, params, workdir, i) if pictures is not None else ():
        print(f"picture: {path}", flush=True)
    return png


def _main_predictor(cfg: Config, fns: dict) -> str:
    """Returns the name of the method's own predictor among `fns` (the method's name, else the last one)."""
    return cfg.method if cfg.method in fns else list(fns)[-1]
