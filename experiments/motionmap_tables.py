"""MotionMap's two small-K protocols for every method of the library: K = 7 against training-window
multimodal ground truth (MotionMap Tables 1-2) and K = 5 against test-window ground truth (Tables 3-4).

    python experiments/motionmap_tables.py RUN_DIR [RUN_DIR ...] --data ../shared/data/bandai-namco-2 \
        --out ~/jaxmotion-runs/motionmap_tables [--train-missing] [--markdown experiments/results/motionmap_tables_bandai.md]

Every RUN_DIR is a trained run on the same data (config from `predictor.run_config`). Each is evaluated
by `experiment.evaluate` with `Config.mm_ground_truth` set to "motionmap-train" at K = 7 and to
"motionmap-test" at K = 5 (MotionMap's multimodal ground truth, protocol §2 (docs/pages/protocol.md#metrics) option: the last
three observed frames as descriptor, candidates and their futures motion-transferred onto the
window's skeleton, the dataset's threshold) and `--protocol-mm` adds the protocol's own ("test": last
pose, no transfer) at both K for comparison. Records go to `OUT/<parent>_<run name>/metrics_<protocol>.json`;
nothing is written into RUN_DIR.

A method that trains one second stage per K (DLow's Q network, MOJO's per-band DLow) has no sampler
at a K it was not trained for: with `--train-missing` the run is copied to `OUT/<parent>_<run name>/run` and
the missing stage is trained there at the run's own settings (`experiment.train(..., resume=True)`
trains only what is missing); without it the table says the sampler is missing. MotionMap gives its
top-K peaks (its own rule when a window has fewer peaks than K: `methods.motionmap`).

`--method-option NAME=VALUE` (repeatable) evaluates with a field of the runs' method config
changed, for the runs whose method config has that field (e.g. `peak_threshold_rel=0.1` for
MotionMap's peak extraction; the trained parameters are the run's); their records go to
`OUT/<parent>_<run name>_NAME-VALUE/` and their table rows carry that label.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import time
from pathlib import Path

PROTOCOLS = {  # name: (K, Config.mm_ground_truth)
    "k7_train": (7, "motionmap-train"),
    "k5_test": (5, "motionmap-test"),
}
PROTOCOL_MM = {"k7_protocol": (7, "test"), "k5_protocol": (5, "test")}
COLUMNS = ("APD", "ADE", "FDE", "MMADE", "MMFDE")
OPTIONAL = ("CMD", "FID", "distinct_futures")  # when every record has them (action labels; MotionMap runs: ANP + 1 for all peaks)


def run_label(run: Path) -> str:
    """Returns `parent_name` of a run folder: two runs of the same name in different folders stay apart."""
    return f"{run.parent.name}_{run.name}"


def _needs_stage(method, cfg, ds, params, k: int) -> bool:
    return method.name not in method.predictors(cfg, ds, params, k)


def parse_options(items: list[str]) -> dict:
    """Returns `{name: value}` of `NAME=VALUE` strings, each value read as a Python literal where it is one."""
    import ast

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.isidentifier():
            raise SystemExit(f"--method-option {item!r}: expected NAME=VALUE")
        try:
            out[name] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            out[name] = value
    return out


def with_options(cfg, options: dict):
    """Returns `(cfg with the method-config fields of `options` replaced, label suffix)`; fields it lacks are left out."""
    mc = cfg.method_config
    fields = {f.name for f in dataclasses.fields(mc)} if dataclasses.is_dataclass(mc) else set()
    use = {k: v for k, v in options.items() if k in fields}
    if not use:
        return cfg, ""
    suffix = "".join(f"_{k}-{v}" for k, v in sorted(use.items()))
    return dataclasses.replace(cfg, method_config=dataclasses.replace(mc, **use)), suffix


def evaluate_run(run: Path, out: Path, protocols: dict, data: str | None, train_missing: bool, options: dict | None = None) -> list[dict]:
    from jaxmotion import experiment as ex
    from jaxmotion.methods import get_method
    from jaxmotion.tools.predictor import run_config

    cfg, source = run_config(run)
    method = get_method(cfg.method)
    ds = ex.load_data(cfg, data or source)
    prep = ex.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    params = ex.restore(cfg, prep, run)
    cfg, suffix = with_options(ex.resolve(cfg), options or {})
    label = run_label(run) + suffix
    dest = out / label
    dest.mkdir(parents=True, exist_ok=True)
    ks = sorted({k for k, _ in protocols.values()})
    missing = [k for k in ks if _needs_stage(method, cfg, ds, params, k)]
    if missing and train_missing:
        copy = dest / "run"
        if not copy.exists():
            print(f"{run.name}: copying the run to {copy} to train the K = {missing} stage(s)", flush=True)
            shutil.copytree(run, copy, ignore=shutil.ignore_patterns("*.png", "*.gif"))
        cfg_k = dataclasses.replace(cfg, eval_k=tuple(sorted(set(cfg.eval_k) | set(missing))))
        t0 = time.perf_counter()
        params = ex.train(cfg_k, prep, copy, resume=True)
        print(f"{run.name}: trained the missing stage(s) in {time.perf_counter() - t0:.0f}s", flush=True)
        cfg, missing = cfg_k, []
    records = []
    for name, (k, mm_source) in protocols.items():
        f = dest / f"metrics_{name}.json"
        if f.is_file():
            records += json.loads(f.read_text())
            continue
        c = dataclasses.replace(cfg, eval_k=(k,), mm_ground_truth=mm_source)
        scratch = dest / f"eval_{name}"
        recs = ex.evaluate(c, prep, params, scratch)
        for r in recs:
            r["run"], r["protocol"], r["label"] = str(run), name, label
            r["missing_stage"] = k in missing
        f.write_text(json.dumps(recs, indent=1, default=float))
        shutil.rmtree(scratch, ignore_errors=True)
        records += recs
    return records


def markdown(records: list[dict], protocols: dict) -> str:
    lines = []
    for name, (k, mm_source) in protocols.items():
        rows = [r for r in records if r.get("protocol") == name]
        if not rows:
            continue
        r0 = rows[0]
        cols = COLUMNS + tuple(c for c in OPTIONAL if all(c in r["metrics"] for r in rows))
        lines += [
            f"K = {k}, MM ground truth `{mm_source}` ({r0['n_windows']} test windows; MM set sizes per run below)",
            "",
            "| run | predictor | " + " | ".join(cols) + " | MM mean | MM only self |",
            "| --- | --- | " + " | ".join("---" for _ in cols) + " | --- | --- |",
        ]
        seen = set()
        for r in rows:
            label = r.get("label", run_label(Path(r["run"])))
            key = (r["method"], label)
            if r["method"] == "zero_velocity" and "zero_velocity" in {s[0] for s in seen}:
                continue  # one zero-velocity row is enough: it does not depend on the run
            seen.add(key)
            m = r["metrics"]
            vals = " | ".join(f"{m[c]:.4f}" if c not in ("APD", "CMD") else f"{m[c]:.3f}" for c in cols)
            lines.append(f"| {label} | {r['method']} | {vals} | {m['MM_mean']:.1f} | {m['MM_only_self_frac']:.2f} |")
        missing = sorted({r.get("label", run_label(Path(r["run"]))) for r in rows if r.get("missing_stage")})
        if missing:
            lines.append(f"\nNo K = {k} sampler of their own method (a per-K stage not trained): {', '.join(missing)}.")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--data", default=None, help="dataset path (default: each run's own)")
    ap.add_argument("--out", type=Path, required=True, help="folder for the records (one subfolder per run)")
    ap.add_argument("--train-missing", action="store_true", help="train a per-K stage a run lacks, in a copy of the run")
    ap.add_argument("--protocol-mm", action="store_true", help="also evaluate at both K with the protocol's MM ground truth")
    ap.add_argument("--markdown", type=Path, default=None, help="write the tables to this file too")
    ap.add_argument("--method-option", action="append", default=[], metavar="NAME=VALUE",
                    help="evaluate with this method-config field changed (runs whose method config has it)")
    args = ap.parse_args(argv)
    options = parse_options(args.method_option)
    protocols = {**PROTOCOLS, **(PROTOCOL_MM if args.protocol_mm else {})}
    for run in args.runs:
        if not run.is_dir():
            ap.error(f"{run}: not a folder")
    records = []
    for run in args.runs:
        t0 = time.perf_counter()
        records += evaluate_run(run.expanduser().absolute(), args.out.expanduser(), protocols, args.data, args.train_missing, options)
        print(f"{run}: done in {time.perf_counter() - t0:.0f}s", flush=True)
    text = markdown(records, protocols)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
