"""MOJO with vs without recursive projection on Bandai-Namco-2 markers (the body-model issue's table).

    python experiments/mojo_projection_table.py --workdir runs/mojo_bandai_markers [--windows 32]

Restores the MOJO model trained by `experiments/configs/mojo_bandai_markers.py` and evaluates, on
the same evenly spaced test windows and with the same latents (same key), "mojo" (the decoder's
markers) and "mojo_proj" (every predicted frame replaced by the fitted body's markers and fed
back, `jaxmotion.methods.mojo.projected_sampler`), plus zero-velocity. Realism metrics: bone
deformation (BDF, the std over time of the distance between the two markers on each limb bone,
summed over the 8 bones, m), body deformation per rigid part (mm), foot skating ratio, FSE.
A subset, because projection fits the body K x t_pred = 3,000 times per window. Writes
`experiments/results/mojo_projection_bandai.{json,md}`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import jax
import numpy as np

from jaxmotion import experiment
from jaxmotion.eval import realism
from jaxmotion.config import load_config

ROOT = Path(__file__).resolve().parents[1]
COLS = [("APD", "APD", 3), ("ADE", "ADE", 3), ("FDE", "FDE", 3), ("MMADE", "MMADE", 3), ("MMFDE", "MMFDE", 3),
        ("BDF", "BDF (m)", 4), ("deform_head", "head (mm)", 1), ("deform_upper_torso", "upper torso (mm)", 1),
        ("deform_lower_torso", "lower torso (mm)", 1), ("foot_skating", "foot skating", 3), ("FSE", "FSE", 3)]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default=str(ROOT / "experiments/configs/mojo_bandai_markers.py"))
    ap.add_argument("--data", default=None, help="Bandai-Namco-2 folder (default: the config's)")
    ap.add_argument("--workdir", required=True, help="where the config's training wrote its checkpoints")
    ap.add_argument("--windows", type=int, default=128, help="evenly spaced test windows")
    ap.add_argument("--batch", type=int, default=16, help="windows per jitted call")
    ap.add_argument("--max-steps", type=int, default=None, help="LM steps per stage (default: the config's)")
    ap.add_argument("--out", default=str(ROOT / "experiments/results/mojo_projection_bandai"))
    ap.add_argument("--reuse", action="store_true", help="re-render from OUT.json instead of evaluating again")
    args = ap.parse_args()

    cfg = load_config(args.config)
    m = cfg.method_config
    m = dataclasses.replace(m, baselines=("zero_velocity", "mojo_proj"), proj_max_steps=args.max_steps or m.proj_max_steps)
    cfg = dataclasses.replace(cfg, method_config=m, eval_batch=args.batch, max_test_windows=args.windows)
    ds = experiment.load_data(cfg, args.data)
    prep = experiment.prepare(ds, cfg.max_test_windows)
    params = None if args.reuse else experiment.restore(cfg, prep, Path(args.workdir))
    t0 = time.perf_counter()
    out = Path(args.out)
    if args.reuse:
        records = [r for r in json.loads(out.with_suffix(".json").read_text()) if r["method"] != "ground_truth"]
        wall = sum(r["wall_s"] for r in records)
    else:
        records = experiment.evaluate(cfg, prep, params, Path(args.workdir) / "projection_eval", data_label=ds.name)
        wall = time.perf_counter() - t0
    # Reference: the realism metrics of the true futures themselves (a valid body by construction).
    gt = realism.window_realism(prep.y[:, None], prep.y, ds)
    records.append({
        "dataset": ds.name, "method": "ground_truth", "K": 1, "n_windows": int(len(prep.y)),
        "metrics": {k: float(np.mean(v)) for k, v in gt.items()}, "wall_s": 0.0,
    })  # fmt: skip

    names = {"ground_truth": "ground truth (reference)", "mojo": "MOJO (no projection)", "mojo_proj": "MOJO + recursive projection", "zero_velocity": "zero-velocity"}
    lines = [
        f"Bandai-Namco-2 markers ({len(ds.info['point_names'])} `bandai` markers, canonical frames), K = {cfg.eval_k[0]}, "
        f"{len(prep.x)} evenly spaced protocol test windows, "
        f"{cfg.method_config.proj_max_steps} LM steps per stage. Command: `python experiments/mojo_projection_table.py "
        f"--workdir {args.workdir} --windows {args.windows}` ({wall / 60:.1f} min, jax {jax.__version__}, "
        f"{jax.devices()[0].platform}).",
        "",
        "| method | " + " | ".join(c[1] for c in COLS) + " | wall s |",
        "| --- | " + " | ".join("---" for _ in COLS) + " | --- |",
    ]
    for r in records:
        mt = r["metrics"]
        vals = " | ".join(f"{mt[k]:.{p}f}" if k in mt else "-" for k, _, p in COLS)
        lines.append(f"| {names.get(r['method'], r['method'])} | {vals} | {r['wall_s']:.0f} |")
    md = "\n".join(lines) + "\n"
    print(md)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".md").write_text(md)
    with open(out.with_suffix(".json"), "w") as f:
        json.dump(records, f, indent=1, default=float)


if __name__ == "__main__":
    main()
