"""A trained or shipped model measured on a folder of your own BVH clips, every clip a test clip, under the protocol.

    jaxmotion eval --model bandai --data my_clips/ --workdir runs/eval_my_clips     # writes metrics.json

The folder is read as `data.datasets.load_bvh_folder` reads it (each file in metres by its own unit,
checked against a person's size; resampled from its own frame rate to the model's), its joints are
matched to the model's (`joint_maps.match_skeleton`: a joint map, the names, or a built-in
convention; the hierarchy checked), and the protocol's test windows (stride `t_his`, [protocol §4][datasets])
of the model's `t_his -> t_pred` are scored with the model's predictors (`experiment.evaluate`:
APD, ADE, FDE, MMADE, MMFDE, ADE-m, FDE-m; multimodal ground truth over the folder's windows at the
model's threshold), with FFE (the first predicted frame's error, `eval.metrics.first_frame_error`) beside them.
A clip of other proportions than the model's training data is retargeted (`predictor.retargeted`, unless
`retarget=False`): the model sees each observed window on its own skeleton, and its futures are put back on
the window's bones before they are scored against the clip's own future.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from jaxmotion import experiment
from jaxmotion.config import check_memory
from jaxmotion.data.datasets import load_bvh_folder
from jaxmotion.data.types import MotionDataset
from jaxmotion.errors import DataError, UsageError
from jaxmotion.eval import loop as eval_loop
from jaxmotion.eval.metrics import first_frame_error
from jaxmotion.method import ExtraMetrics, Method
from jaxmotion.tools.joint_maps import match_skeleton
from jaxmotion.tools.predictor import MotionPredictor


def folder_as_test_set(
    model: MotionPredictor, folder: str | Path, *, scale: float | dict[str, float] | None = None,
    joint_map: dict[str, str] | None = None,
) -> tuple[MotionDataset, str]:
    """Returns `(the folder as a dataset of test sequences in the model's layout, how its joints were matched)`."""
    lay = model.layout
    if lay["frames"] != "root_relative":
        raise DataError(folder, f"the model predicts {lay['frames']} marker frames; evaluating on a BVH folder needs a joint model")
    ds = load_bvh_folder(folder, scale=scale, fps=lay["fps"], t_his=lay["t_his"], t_pred=lay["t_pred"],
                         mm_threshold=lay["mm_threshold"])
    mapping, how = match_skeleton(lay["joints"], lay["parents"], ds.skeleton.names, ds.skeleton.parents, joint_map,
                                  where=folder)
    idx = [ds.skeleton.names.index(mapping[n]) for n in lay["joints"]]
    test = [dataclasses.replace(s, positions=np.ascontiguousarray(s.positions[:, idx])) for s in ds.test]
    info = {**ds.info, "up_axis": lay.get("up_axis", ds.info.get("up_axis")), "joint_map": mapping}
    return dataclasses.replace(ds, skeleton=model.skeleton, train=[], test=test, info=info), how


def evaluate_folder(
    model: MotionPredictor, folder: str | Path, workdir: str | Path, *, k: int | None = None,
    scale: float | dict[str, float] | None = None, joint_map: dict[str, str] | None = None, seed: int | None = None,
    retarget: bool = True,
) -> list[str]:
    """Writes `workdir/metrics.json` (one record per predictor, [protocol §6][reporting]) and returns the lines to print."""
    if k is not None and not (isinstance(k, int) and k >= 1):
        raise UsageError(f"--k (the number of futures) must be an integer >= 1, got {k!r}")
    ds, how = folder_as_test_set(model, folder, scale=scale, joint_map=joint_map)
    k = model.default_k if k is None else k
    check_memory(dataclasses.replace(model.config, eval_k=(k,)), ds.dim, ds.t_his, ds.t_pred, source=f"--k {k}")
    cfg = dataclasses.replace(model.config, eval_k=(k,), action_metrics=False, max_test_windows=None,
                              seed=model.config.seed if seed is None else seed, mm_ground_truth="test", mm_deviation=None)
    prep = experiment.prepare(ds, None, test_only=True)
    workdir = Path(workdir)
    retarget = retarget and model.bone_lengths is not None  # a run whose manifest has no skeleton is shown the clips as they are
    label = f"{ds.name} (every clip a test clip{', retargeted onto the model' if retarget else ''})"
    records = eval_loop.evaluate(cfg, folder_method(model, retarget), prep, model.params, workdir, label)
    clips = ", ".join(sorted(s.name for s in ds.test)[:6])
    short = sorted(s.name for s in ds.test if len(s.positions) <= ds.t_his + ds.t_pred)
    return [
        f"data: {folder}: {len(ds.test)} clips, all test ({clips}{', ...' if len(ds.test) > 6 else ''}); {how}; "
        f"{ds.t_his}->{ds.t_pred} frames at {round(ds.fps, 2):g} fps (files at {', '.join(f'{round(r, 2):g}' for r in ds.info['file_fps'])} fps), "
        f"{len(prep.windows)} test windows",
        *([f"skipped: {len(short)} clip(s) not longer than t_his + t_pred = {ds.t_his + ds.t_pred} frames: {', '.join(short)}"] if short else []),
        f"model: {model.run_dir} ({model.manifest['dataset']['name']}, {model.config.method}), K={k}",
        f"wrote {workdir / 'metrics.json'} ({len(records)} records)",
    ]


def folder_method(model: MotionPredictor, retarget: bool = True) -> Method:
    """Returns the model's method with the model's own predictors (retargeted when `retarget`, `MotionPredictor.predictors`)
    and FFE (`first_frame_error`) added to its own metrics."""
    own = model.method.extra_metrics

    def extra(cfg, ds, params) -> ExtraMetrics:
        mine = own(cfg, ds, params) if own is not None else None

        def per_window(pred: np.ndarray, gt: np.ndarray) -> dict[str, np.ndarray]:
            out = {"FFE": np.asarray(first_frame_error(pred, gt))}
            return {**out, **mine.per_window(pred, gt)} if mine is not None else out

        return ExtraMetrics(per_window, mine.record if mine is not None else {})

    return dataclasses.replace(model.method, predictors=lambda cfg, ds, params, k: model.predictors(k, retarget),
                               extra_metrics=extra)
