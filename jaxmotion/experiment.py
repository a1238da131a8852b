"""The job behind the `jaxmotion` command: data -> train a method -> protocol evaluation -> report.

Every step is also callable from Python. A work directory holds one folder per training stage
(`cvae/`, `dlow_k50/`, ... each with `ckpt/`, `log.jsonl` and `stage.json`), `metrics.json`
([protocol §6][reporting] records, one per (predictor, K)), `samples.png` and `samples.gif` (observed motion
and K predicted futures, still and animated) and `predictor.json` (what `jaxmotion.load` needs to
predict from the run alone). The method is looked up in the registry (`jaxmotion.method`) and its stages
are run by the one stage runner (`jaxmotion.train.runner`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.train import distributed
from jaxmotion.config import Config, check_memory
from jaxmotion.data.datasets import BANDAI_TARBALL, load_dataset
from jaxmotion.data.folder_split import folder_split
from jaxmotion.data.prepare import Prepared, check_lengths, prepare
from jaxmotion.data.synthetic import make_synthetic
from jaxmotion.data.types import MotionDataset
from jaxmotion.data.validation import validation_split
from jaxmotion.errors import UsageError
from jaxmotion.eval import loop as eval_loop
from jaxmotion.eval.loop import format_record, predict_chunks
from jaxmotion.method import Predictor
from jaxmotion.methods import get_method
from jaxmotion.eval.metrics import multimodal_gt
from jaxmotion.train.manifest import MANIFEST, write_manifest
from jaxmotion.train import runner

__all__ = ["get_method", "resolve", "load_data", "Prepared", "prepare", "check_lengths", "train", "restore", "predictors",
           "evaluate", "report", "Predictor", "format_record", "predict_chunks"]


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
        if test_files:
            raise UsageError(f"--test-files applies to a plain folder of BVH clips; the synthetic dataset has its own split, got {test_files}")
        if cfg.data_options:
            raise ValueError(f"the synthetic dataset takes no data_options, got {sorted(cfg.data_options)}")
        return make_synthetic(cfg.seed)
    path = Path(spec).expanduser()
    options = dict(cfg.data_options)
    if plain_bvh_folder(path) and "split" not in options:
        split, how = folder_split(path, test_files)
        ds = load_dataset(spec, split=lambda f: split.get(f, "test"), **options)
        ds.info["split"] = how
        return ds
    if test_files:
        raise UsageError(f"--test-files applies to a plain folder of BVH clips; {spec} has its own protocol split")
    return load_dataset(spec, **options)


def plain_bvh_folder(path: Path) -> bool:
    """Returns whether `path` is a folder of BVH files that no dataset protocol (Bandai-Namco-2) claims."""
    if not path.is_dir() or (path / BANDAI_TARBALL).is_file() or any(path.glob("dataset-2_*.bvh")):
        return False
    return any(path.rglob("*.bvh"))


def train(cfg: Config, prep: Prepared, workdir: str | Path, resume: bool = False) -> dict:
    """Returns `{stage name: parameters}` after training every stage of the config's method (`runner.train`).

    Writes `workdir/predictor.json` first (`jaxmotion.tools.predictor`): what `jaxmotion.load` needs to predict.
    A config whose largest allocation exceeds the memory here (`config.check_memory`) is refused before that.
    """
    method = get_method(cfg.method)
    ds = prep.dataset
    check_memory(cfg, ds.dim, ds.t_his, ds.t_pred)  # before the manifest or a step: refused with its estimate
    if distributed.is_main():
        write_manifest(cfg, prep.dataset, workdir)
    curve = eval_loop.learning_curve(cfg, method, prep) if cfg.curve_every > 0 else None
    return runner.train(method, cfg, prep, workdir, resume=resume, curve=curve)


def restore(cfg: Config, prep: Prepared, workdir: str | Path) -> dict:
    """Returns `{stage name: parameters}` of a trained work directory (`runner.restore`)."""
    return runner.restore(get_method(cfg.method), cfg, prep, workdir)


def predictors(cfg: Config, ds: MotionDataset, params: dict, k: int) -> dict[str, Predictor]:
    """Returns the method's jitted K-future predictors by name."""
    return get_method(cfg.method).predictors(cfg, ds, params, k)


def evaluate(
    cfg: Config, prep: Prepared, params, workdir: Path, data_label: str | None = None, manifest: bool = True
) -> list[dict]:
    """Returns and writes (`workdir/metrics.json`) one [protocol §6][reporting] record per (predictor, K) (`jaxmotion.eval.evaluate`).

    `cfg` is resolved (`resolve`). `manifest`: write `predictor.json` when the work directory has
    none (False when `workdir` holds the evaluation of a model trained elsewhere).
    """
    if manifest and not (Path(workdir) / MANIFEST).exists():  # a run trained before `predictor.json` existed
        write_manifest(cfg, prep.dataset, workdir)
    return eval_loop.evaluate(cfg, get_method(cfg.method), prep, params, Path(workdir), data_label)


def most_multimodal(prep: Prepared, n: int) -> np.ndarray:
    """Returns the indices `(n,)` of the `n` test windows whose multimodal ground truth is most spread, most spread first.

    The spread of window i is the mean distance of its MM futures' end poses ([protocol §2][metrics] sets)
    from its own true end pose: where a good stochastic predictor should show several distinct futures.
    """
    idx, mask = multimodal_gt(prep.x[:, -1], prep.dataset.mm_threshold)
    idx, mask = np.asarray(idx), np.asarray(mask)
    ends = prep.y[:, -1]
    spread = (np.linalg.norm(ends[idx] - ends[:, None], axis=-1) * mask).sum(1) / mask.sum(1)
    return np.argsort(-spread, kind="stable")[:n]


def report(cfg: Config, prep: Prepared, params, workdir: Path, method: str | None = None) -> Path:
    """Writes `workdir/samples.png` and `samples.gif` (animated) for the test window whose ground truth is most multimodal.

    That is the window whose multimodal ground-truth futures ([protocol §2][metrics]) end furthest apart
    on average: where a good stochastic predictor should show several distinct futures. A method
    with `Method.pictures` draws its own pictures of that window too; their paths are printed.
    """
    from jaxmotion.pictures.viz import plot_futures  # matplotlib: imported only when a picture is drawn

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
    from jaxmotion.pictures.animate import animate_futures

    animate_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, workdir / "samples.gif", fps=ds.fps,
                    title=f"{ds.name}: test window {i}, {method}, K={k}; observed, then the futures")
    pictures = get_method(cfg.method).pictures
    for path in pictures(cfg, prep, params, workdir, i) if pictures is not None else ():
        print(f"picture: {path}", flush=True)
    return png


def _main_predictor(cfg: Config, fns: dict) -> str:
    """Returns the name of the method's own predictor among `fns` (the method's name, else the last one)."""
    return cfg.method if cfg.method in fns else list(fns)[-1]
