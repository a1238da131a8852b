"""The shipped models: export a trained run small, measure it, choose the default by a stated rule, write the cards.

    ~/jaxmotion-runs/quiet python experiments/shipped_models.py measure dlow ~/jaxmotion-runs/ship/dlow
    python experiments/shipped_models.py ship

`measure NAME RUN` exports the run (trained on the validation split of Bandai-Namco-2, the configs
`experiments/configs/*_bandai_val.py`) to `jaxmotion/pretrained/bandai_NAME.msgpack` with float16
parameters, the training data's facing and motion ranges (`train.manifest`), checks that the float16 file predicts within 1 mm of the
run, and measures the file at K = 50 on the held-back validation windows (what the default is chosen
on), on the protocol's test windows (reported, never used to choose) and on ../shared/data/cmu-bvh
(every clip a test clip, retargeted onto the model, beside zero-velocity and without retargeting);
~3-5 min per model on two CPU cores. The record goes to `experiments/results/shipped_models.json`.

`blend RUN METHOD` sweeps the length of the blend from the observed motion into a retargeted model's
futures (`predictor.RETARGET_BLEND_S`, chosen on validation windows: experiments/results/retarget_blend.md).

`revalidate NAME --max-windows N` measures a shipped file again on N validation windows, so that every
model is compared on the same windows.

`ship` chooses the default (`jaxmotion predict --model bandai`) by the rule `RULE` and writes
`jaxmotion/pretrained/models.json` (read by `jaxmotion models` and `jaxmotion.load`) and the model
cards `jaxmotion/pretrained/README.md`, both generated from the results file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from jaxmotion import experiment  # noqa: E402
from jaxmotion.eval import loop as eval_loop  # noqa: E402
from jaxmotion.tools.evaluate_folder import evaluate_folder, folder_method  # noqa: E402
from jaxmotion.tools.predictor import PRETRAINED_DIR, MotionPredictor, export, load  # noqa: E402
from jaxmotion.train.manifest import facing, motion_ranges  # noqa: E402

BANDAI = ROOT.parent / "shared" / "data" / "bandai-namco-2"
CMU = ROOT.parent / "shared" / "data" / "cmu-bvh"
RESULTS = ROOT / "experiments" / "results" / "shipped_models.json"
KEEP = ("APD", "ADE", "FDE", "MMADE", "MMFDE", "FFE")
RULE = "the lowest ADE at K = 50 on the validation windows (held-back training clips of Bandai-Namco-2)"
LICENCE = "CC BY-NC 4.0 (as its training data, Bandai-Namco-Research-Motiondataset-2; attribution: Bandai Namco Research Inc.)"
DATA = ("Bandai-Namco-2 under the protocol's datasets section (§4; 21 joints, Hips root, 30 fps, 15 -> 60 frames, metres), "
        "trained on the validation split's training clips (styles active, exhausted, feminine, masculine; one clip in five held back)")


def _metrics(records: list[dict]) -> dict[str, dict[str, float]]:
    return {r["method"]: {k: round(float(r["metrics"][k]), 4) for k in KEEP if k in r["metrics"]} for r in records}


def _split(model: MotionPredictor, split: str, max_windows: int | None = None):
    """Returns `(the evaluation config, the Bandai-Namco-2 dataset of `split` in the model's config)`."""
    cfg = dataclasses.replace(model.config, split=split, eval_k=(50,), action_metrics=False, max_test_windows=max_windows)
    return cfg, experiment.load_data(cfg, str(BANDAI))


def _bandai(model: MotionPredictor, cfg, ds, work: Path) -> dict:
    """Returns the metrics by predictor on the dataset's test windows (the validation split's held-back windows, or the test's)."""
    prep = experiment.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    records = eval_loop.evaluate(cfg, folder_method(model, retarget=False), prep, model.params, work / cfg.split, f"bandai2 {cfg.split}")
    return {"n_windows": len(prep.windows), **_metrics(records)}


def measure(name: str, run: Path, max_windows: int | None = None, stages: tuple[str, ...] | None = None) -> dict:
    """Exports `run` as `bandai_NAME.msgpack` and returns its record (module docstring)."""
    t0 = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix=f"shipped_{name}_"))
    trained = load(run, stages)
    cfg, val = _split(trained, "val", max_windows)
    face = facing(val)  # of the training clips the run was trained on
    out = export(run, PRETRAINED_DIR / f"bandai_{name}.msgpack", stages, float16=True, manifest={"facing": face, "motion_ranges": motion_ranges(val)})
    model = load(out)
    x, key = experiment.prepare(val, 64).x, jax.random.key(0)
    drift = max(float(np.abs(model.predict(x, 50, key, m) - trained.predict(x, 50, key, m)).max()) for m in model.methods)
    validation = _bandai(model, cfg, val, work)
    test = _bandai(model, *_split(model, "test", max_windows), work)
    cmu = {}
    for retarget in (True, False):
        evaluate_folder(model, CMU, work / f"cmu_{retarget}", k=50, retarget=retarget)
        records = json.loads((work / f"cmu_{retarget}" / "metrics.json").read_text())
        cmu["retargeted" if retarget else "as_recorded"] = {"n_windows": records[0]["n_windows"], **_metrics(records)}
    return {
        "name": name, "file": out.name, "method": model.config.method, "predictor": model.main_method(50),
        "run": str(run), "config": f"experiments/configs/{model.config.name.removesuffix('_rule')}.py", "seed": model.config.seed,
        "size_bytes": out.stat().st_size, "storage": "float16", "float16_max_drift_m": drift, "facing": face,
        "validation": validation, "test": test, "cmu": cmu,
        "device": f"{jax.devices()[0].platform} ({jax.devices()[0].device_kind})", "wall_s": round(time.perf_counter() - t0, 1),
    }


def ship(results: dict) -> tuple[dict, str]:
    """Returns `(models.json, README.md)`: the default chosen by `RULE`, and the cards."""
    models = sorted(({**m, "name": f"bandai-{m['name']}", "stages": sorted(load(PRETRAINED_DIR / m["file"]).params)}
                     for m in results.values()), key=lambda m: m["name"])
    best = min(models, key=lambda m: m["validation"][m["predictor"]]["ADE"])
    reg = {"default": best["name"], "rule": RULE, "licence": LICENCE, "data": DATA, "models": [
        {k: m[k] for k in ("name", "file", "method", "predictor", "stages", "config", "seed", "size_bytes", "storage",
                           "float16_max_drift_m")}
        | {"metrics": {"validation": m["validation"][m["predictor"]], "test": m["test"][m["predictor"]],
                       "cmu": m["cmu"]["retargeted"][m["predictor"]], "cmu_zero_velocity": m["cmu"]["retargeted"]["zero_velocity"]}}
        for m in models]}
    return reg, cards(reg, models)


def _row(label: str, m: dict) -> str:
    return f"| {label} | " + " | ".join(f"{m[k]:.3f}" if k in m else "-" for k in KEEP) + " |"


def cards(reg: dict, models: list[dict]) -> str:
    """Returns the model cards (`jaxmotion/pretrained/README.md`) of the measured models."""
    total = sum(m["size_bytes"] for m in models) / 1e6
    lines = [
        "# Shipped models",
        "",
        "<!-- generated by experiments/shipped_models.py ship from experiments/results/shipped_models.json; do not edit -->",
        "",
        f"{len(models)} models, {total:.1f} MB in all (float16 parameters, computed in float32). `jaxmotion models` lists them;",
        "`jaxmotion predict --model NAME CLIP --out DIR`, `jaxmotion eval --model NAME --data FOLDER` and",
        f"`jaxmotion.load(NAME)` use one. The default, `bandai`, is **{reg['default']}**, chosen by {reg['rule']};",
        "the test windows and the CMU clips only measure the models, they chose nothing.",
        "",
        f"Data: {reg['data']}.",
        "",
        f"Licence: {reg['licence']}: non-commercial use, with attribution "
        "(https://creativecommons.org/licenses/by-nc/4.0/). The rest of jaxmotion keeps its own licence (../../LICENSE).",
        "",
        "A clip of other proportions or facing is retargeted: the model sees the observed window on its own skeleton",
        "(the training data's median bone lengths, the clip's bone directions), turned to the training data's most",
        "common facing, and its futures are put back on the clip's bones (`--no-retarget` to turn it off). FFE is",
        "the first predicted frame's error (best of K): a future that does not continue the observed motion shows there.",
        "All numbers: K = 50, metres, seed of the evaluation draws = the run's seed. Validation and test rows are",
        "measured on evenly spaced windows when the row says fewer than the split's 1,428 validation / 1,609 test windows.",
    ]
    for m in models:
        p = m["predictor"]
        lines += [
            "",
            f"## {m['name']}{' (default: `bandai`)' if m['name'] == reg['default'] else ''}",
            "",
            f"`{m['file']}`, {m['size_bytes'] / 1e6:.1f} MB; method {m['method']}, trained stages {', '.join(m['stages'])} "
            f"(predictor `{p}`), seed {m['seed']}; "
            f"float16 storage moves its futures by at most {1000 * m['float16_max_drift_m']:.3f} mm. Made with",
            "",
            f"    jaxmotion train --config {m['config']} --data ../shared/data/bandai-namco-2 --workdir RUN --seed {m['seed']}",
            f"    python experiments/shipped_models.py measure {m['name'].removeprefix('bandai-')} RUN"
            + (f" --max-windows {m['max_windows']}" if m.get("max_windows") else "") + f" --stages {' '.join(m['stages'])}",
            "",
            "| windows | " + " | ".join(KEEP) + " |",
            "| --- |" + " --- |" * len(KEEP),
            _row(f"validation ({m['validation']['n_windows']}), {p}", m["validation"][p]),
            _row(f"validation, zero-velocity", m["validation"]["zero_velocity"]),
            _row(f"protocol test ({m['test']['n_windows']}), {p}", m["test"][p]),
            _row("protocol test, zero-velocity", m["test"]["zero_velocity"]),
            _row(f"cmu-bvh ({m['cmu']['retargeted']['n_windows']}), {p}, retargeted", m["cmu"]["retargeted"][p]),
            _row(f"cmu-bvh, {p}, as recorded (`--no-retarget`)", m["cmu"]["as_recorded"][p]),
            _row("cmu-bvh, zero-velocity", m["cmu"]["retargeted"]["zero_velocity"]),
        ]
        c, z = m["cmu"]["retargeted"][p], m["cmu"]["retargeted"]["zero_velocity"]
        lines += ["", f"On the CMU clips it is {'below' if c['ADE'] < z['ADE'] else 'not below'} zero-velocity in ADE, "
                      f"{'below' if c['FDE'] < z['FDE'] else 'not below'} it in FDE, and its first-frame error is "
                      f"{c['FFE'] / z['FFE']:.2f} x zero-velocity's."]
    return "\n".join(lines) + "\n"


def revalidate(name: str, max_windows: int) -> dict:
    """Returns the record of `name` with its validation metrics measured again on `max_windows` evenly spaced windows
    (the shipped file), so that every model is compared on the same windows; the earlier ones are kept beside them."""
    results = json.loads(RESULTS.read_text())
    rec = results[name]
    model = load(PRETRAINED_DIR / rec["file"])
    cfg, val = _split(model, "val", max_windows)
    rec[f"validation_{rec['validation']['n_windows']}"] = rec["validation"]
    rec["validation"] = _bandai(model, cfg, val, Path(tempfile.mkdtemp(prefix=f"shipped_{name}_")))
    return rec


def blend_sweep(run: Path, method: str, frames: tuple[int, ...], max_windows: int = 400) -> list[str]:
    """Returns one line per blend length (`predictor.inertialized`): ADE / FDE / FFE of the retargeted predictor on
    `max_windows` evenly spaced validation windows of Bandai-Namco-2 (what `RETARGET_BLEND_S` is chosen on) and on
    the CMU clips (shown, not used to choose)."""
    from jaxmotion.eval.metrics import ade, fde, first_frame_error
    from jaxmotion.tools.evaluate_folder import folder_as_test_set
    from jaxmotion.tools.predictor import retargeted

    model = load(run)
    cfg, val = _split(model, "val", max_windows)
    face = facing(val)
    hips = (face["degrees"], model.skeleton.names.index(face["left"]), model.skeleton.names.index(face["right"]), model.layout["up_axis"])
    sets = {"val": experiment.prepare(val, max_windows), "cmu-bvh": experiment.prepare(folder_as_test_set(model, CMU)[0], None, test_only=True)}
    fn, lines = model.predictors(50)[method], []
    for b in frames:
        g, row = retargeted(fn, model.bone_lengths, model.skeleton.parents, hips, b), [f"blend {b:2d}"]
        for name, p in sets.items():
            f = np.concatenate([np.asarray(g(p.x[i : i + 64], jax.random.fold_in(jax.random.key(0), i))) for i in range(0, len(p.x), 64)])
            row.append(f"{name} ADE {float(ade(f, p.y).mean()):.4f} FDE {float(fde(f, p.y).mean()):.4f} "
                       f"FFE {float(first_frame_error(f, p.y).mean()):.4f}")
        lines.append(" | ".join(row))
    return lines


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("measure")
    s.add_argument("name")
    s.add_argument("run", type=Path)
    s.add_argument("--max-windows", type=int, default=None, help="that many evenly spaced validation and test windows")
    s.add_argument("--stages", nargs="+", default=None, help="only these stages of the run (default: all), e.g. cvae")
    sub.add_parser("ship")
    s = sub.add_parser("revalidate")
    s.add_argument("name")
    s.add_argument("--max-windows", type=int, required=True)
    s = sub.add_parser("blend")
    s.add_argument("run", type=Path)
    s.add_argument("method")
    s.add_argument("--frames", default="0,8,15,30,45,60")
    args = p.parse_args(argv)
    results = json.loads(RESULTS.read_text()) if RESULTS.is_file() else {}
    if args.command == "revalidate":
        results[args.name] = revalidate(args.name, args.max_windows)
        RESULTS.write_text(json.dumps(results, indent=1) + "\n")
        print(json.dumps(results[args.name]["validation"], indent=1))
        return
    if args.command == "blend":
        print("\n".join(blend_sweep(args.run.expanduser(), args.method, tuple(int(f) for f in args.frames.split(",")))), flush=True)
        return
    if args.command == "measure":
        results[args.name] = measure(args.name, args.run.expanduser(), args.max_windows, tuple(args.stages) if args.stages else None)
        results[args.name]["max_windows"] = args.max_windows
        RESULTS.write_text(json.dumps(results, indent=1) + "\n")
        print(json.dumps(results[args.name], indent=1))
    else:
        reg, readme = ship(results)
        (PRETRAINED_DIR / "models.json").write_text(json.dumps(reg, indent=1) + "\n")
        (PRETRAINED_DIR / "README.md").write_text(readme)
        print(f"default: {reg['default']} ({reg['rule']}); wrote {PRETRAINED_DIR / 'models.json'} and README.md")


if __name__ == "__main__":
    main()
