# flock /tmp/jaxmotion-heavy.lock python experiments/projection_effect.py RUN_DIR [RUN_DIR ...] --out experiments/results/projection_bandai.json
#
# What putting the predicted futures on the input's skeleton (as `jaxmotion predict` does before it
# writes BVH files) does to the protocol metrics: every predictor of each trained run is evaluated on
# the run's protocol test windows twice, on the model's output and on that output moved onto the
# window's own bone lengths (its last observed frame; each predicted bone keeps its direction,
# joints rebuilt from the root: `metrics.motion_transfer`, which is what the forward kinematics of
# `retarget.fit_bvh`'s rotations gives when every joint is predicted). Also reports how far the raw
# bone lengths are from the observed ones. Runtime: ~2 min per DLow run on Bandai-Namco-2 (2 cores; 40 s per predictor).
# Results: experiments/results/body.md; the table: docs/pages/results.md ("Futures put on the input's skeleton").
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.tools.predictor import load, run_config
from jaxmotion.eval import evaluate_windows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("runs", nargs="+")
    p.add_argument("--data", default=None, help="the dataset (default: the one each run was trained on)")
    p.add_argument("--out", required=True)
    args = p.parse_args()
    records = []
    for run in args.runs:
        model = load(run)
        cfg, source = run_config(run)
        ds = experiment.load_data(cfg, args.data or source)
        prep = experiment.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
        parents = tuple(int(q) for q in ds.skeleton.parents)
        sets = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold)
        project = jax.jit(lambda f, last: metrics.motion_transfer(f, last[:, None, None], parents))
        lengths = jax.jit(lambda f: metrics.bone_lengths(f, parents))
        k = max(cfg.eval_k)
        for name, fn in model.predictors(k).items():
            if name == "zero_velocity":
                continue  # the observed pose: already on the input's skeleton
            t0 = time.perf_counter()
            out = {}
            length_error = []
            for mode in ("raw", "on_input_skeleton"):
                def chunks():
                    for i, c in enumerate(experiment.predict_chunks(fn, prep.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)):
                        last = jnp.asarray(prep.x[i * cfg.eval_batch : i * cfg.eval_batch + c.shape[0], -1])
                        if mode == "raw":
                            length_error.append(np.asarray(jnp.abs(lengths(c) - lengths(last)[:, None, None]).mean(axis=(1, 2))))
                            yield c
                        else:
                            yield np.asarray(project(jnp.asarray(c), last))

                m = evaluate_windows(chunks(), prep.y, sets)
                out[mode] = {key: round(float(m[key]), 5) for key in ("APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m")}
            err = np.concatenate(length_error)  # (n, bones)
            rec = {
                "run": str(run), "dataset": ds.name, "method": name, "K": k, "n_windows": int(len(prep.x)), "seed": cfg.seed,
                "metrics": out,
                "change": {key: round(out["on_input_skeleton"][key] - out["raw"][key], 5) for key in out["raw"]},
                "raw_bone_length_error_m": {"mean": round(float(err.mean()), 5),
                                            "per_bone": {n: round(float(e), 5) for n, e in zip(ds.skeleton.names[1:], err.mean(0))}},
                "wall_s": round(time.perf_counter() - t0, 1),
            }
            records.append(rec)
            print(json.dumps({k_: rec[k_] for k_ in ("method", "K", "change", "wall_s")}), flush=True)
            print("  raw", out["raw"], "\n  on input skeleton", out["on_input_skeleton"],
                  f"\n  raw bone length error {1000 * err.mean():.1f} mm", flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(records, indent=1))


if __name__ == "__main__":
    main()
