"""DivSamp ablation (the paper's Table 5, reduced): coefficient sampler and diversity loss, sampler stage only.

    flock /tmp/jaxmotion-heavy.lock python experiments/divsamp_ablation.py \
        --config experiments/configs/divsamp_bandai.py --data ../shared/data/bandai-namco-2 \
        --workdir /tmp/runs/divsamp_bandai --steps 100 --windows 300

Every variant trains a fresh sampler on the same trained, frozen CVAE (`<workdir>/cvae`) with the
config's loss weights and a reduced budget (`--steps`, `--batch`, K = the config's `nk`), then is
evaluated at K = 50 on an evenly spaced subset of `--windows` test windows (multimodal ground truth
from all test windows). Variants: Gumbel-Softmax / Uniform-Softmax / Gaussian-Softmax coefficients
with the hinge loss, and Gumbel-Softmax with DLow's exp(-D^2 / d_scale) energy instead of the hinge
(same weight lambda_div). Writes `<out>.json` and `<out>.md`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import jax

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.config import load_config
from jaxmotion.methods import divsamp as divsamp_method
from jaxmotion.methods import get_method
from jaxmotion.train import runner
from jaxmotion.eval import evaluate_windows

VARIANTS = {
    "gumbel + hinge": {"coefficients": "gumbel", "diversity": "hinge"},
    "uniform + hinge": {"coefficients": "uniform", "diversity": "hinge"},
    "gaussian + hinge": {"coefficients": "gaussian", "diversity": "hinge"},
    "gumbel + exp (DLow energy)": {"coefficients": "gumbel", "diversity": "exp"},
}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True)
    p.add_argument("--data", default=None)
    p.add_argument("--workdir", required=True, help="folder with the trained CVAE (cvae/)")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--k", type=int, default=50, help="K at evaluation")
    p.add_argument("--windows", type=int, default=300)
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--out", default="experiments/results/divsamp_ablation_bandai")
    args = p.parse_args(argv)

    cfg = load_config(args.config)
    ds = experiment.load_data(cfg, args.data)
    full = experiment.prepare(ds)
    sub = experiment.prepare(ds, args.windows)
    base = divsamp_method.settings(cfg)
    work = Path(args.workdir)
    method = get_method("divsamp")
    cvae_variables = runner.restore_stage(method, divsamp_method.cvae_stage(cfg, full, base), work, {})
    rows = []
    for name in args.variants:
        d = dataclasses.replace(base, num_steps=args.steps, batch_size=args.batch, **VARIANTS[name])
        stage = "ablation_" + "_".join(VARIANTS[name].values()) + f"_s{args.steps}"
        t0 = time.perf_counter()
        stage_def = divsamp_method.sampler_stage(cfg, full, divsamp_method.divsamp.check_config(d), name=stage)
        sampler = runner.run_stage(method, stage_def, cfg, work, {"cvae": cvae_variables}, resume=True)
        train_s = time.perf_counter() - t0
        fn = divsamp_method.make_predictors(d, ds, cvae_variables, sampler, args.k)["divsamp"]
        chunks = experiment.predict_chunks(fn, sub.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)
        m = evaluate_windows(
            chunks, sub.y, sub.x[:, -1], thr=ds.mm_threshold,
            reference_last_poses=full.x[:, -1], reference_futures=full.y,
        )
        log = [json.loads(line) for line in (work / stage / "log.jsonl").read_text().splitlines()]
        rec = {"variant": name, "K": args.k, "n_windows": len(sub.x), "steps": args.steps, "batch": args.batch,
               "train_s": round(train_s, 1), "first_loss": log[0]["loss"], "last_loss": log[-1]["loss"],
               **{key: float(m[key]) for key in metrics.METRIC_NAMES}}
        rows.append(rec)
        print(json.dumps(rec), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"dataset": ds.name, "config": args.config, "n_test_windows": len(full.x), "windows": [int(i) for i in sub.keep],
            "loss_weights": {k: getattr(base, k) for k in ("lambda_kl", "lambda_acc", "lambda_div", "eta", "d_scale", "tau", "nk")}}
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    keys = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m"]
    lines = ["| variant | " + " | ".join(keys) + " |", "| --- |" + " --- |" * len(keys)]
    lines += [f"| {r['variant']} | " + " | ".join(f"{r[k]:.4f}" for k in keys) + " |" for r in rows]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
