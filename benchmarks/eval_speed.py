"""Evaluation speed on Bandai-Namco-2, against two targets (each part under 30 s once compiled): compile time and run time apart, metric values shown.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/eval_speed.py      # both targets (quiet machine: about 3 minutes)
    python benchmarks/eval_speed.py --only eval                          # (a) alone
    python benchmarks/eval_speed.py --only k1000                         # (b) alone
    python benchmarks/eval_speed.py --precision float32 bf16 --noise-seed 1   # bf16 products beside float32, one run

(a) `jaxmotion eval` of the DLow run (config experiments/configs/dlow_bandai.py; 1,609 test windows,
    K = 50, three samplers: zero-velocity, the CVAE from N(0, I), DLow), run through the command
    itself on a copy of the run folder in a temporary directory (the command writes metrics.json
    and pictures there). Target: the evaluation under 30 s once compiled, i.e. the sum over the
    samplers of their records' `wall_s - compile_s`.
(b) The K = 1000 point of `experiments/divsamp_k_sweep.py` (DivSamp, 200 evenly spaced test windows,
    sampling included, MM sets over all test windows). Target: under 30 s once compiled.

Each part prints the CPU model, the time spent compiling (jax's own compile events,
`jaxmotion.train.compile_time`) and the rest, and the metric values beside a reference (for (a) the run's
own metrics.json, for (b) the previous run of this script, `--out`), so a speed-up that changes the
numbers shows; (a) also times each sampler's sampling alone, to say where the time goes. The run
folders are only read. Timings mean something only on a quiet machine (hence the lock).

`--precision float32 bf16` runs both parts once per precision (`Config.precision`, the trained
float32 weights evaluated with bfloat16 products, jaxmotion/nn/precision.py), each beside the same
reference, so the speed ratio and the change in the metrics come from one run. `--noise-seed S`
adds (a) in float32 with the evaluation's sampling seed S instead of the config's: how much the
metrics move with the noise draws alone, the yardstick for "unchanged within run-to-run noise".
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine  # noqa: E402
from benchmarks.peak import cpu_flags, has_bf16  # noqa: E402

RUNS = Path.home() / "jaxmotion-runs" / "issue11"
DATA = ROOT.parent / "shared" / "data" / "bandai-namco-2"
TARGET_S = 30.0
SHOWN = ("APD", "ADE", "FDE", "MMADE", "MMFDE")


def _metrics_line(m: dict, ref: dict | None) -> str:
    line = " ".join(f"{k} {m[k]:.6f}" for k in SHOWN)
    if ref:
        line += "  (reference " + " ".join(f"{ref[k]:.6f}" for k in SHOWN) + "; max |diff| "
        line += f"{max(abs(m[k] - ref[k]) for k in SHOWN):.2e})"
    return line


def _verdict(run_s: float) -> str:
    return f"target < {TARGET_S:.0f} s: {'met' if run_s < TARGET_S else 'MISSED'}"


def eval_target(run: Path, config: Path, data: Path, precision: str = "float32", seed: int | None = None) -> list[dict]:
    """Returns the records (metrics.json) of `jaxmotion eval` on a copy of `run`, after printing their timings."""
    from jaxmotion.cli import main

    stored = run / "metrics.json"  # the run's own evaluation, if it has one: the reference values
    ref = {(r["method"], r["K"]): r["metrics"] for r in json.loads(stored.read_text())} if stored.exists() else {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / run.name
        shutil.copytree(run, work, ignore=shutil.ignore_patterns("*.png", "*.gif", "metrics.json"))
        t0 = time.perf_counter()
        extra = ["--precision", precision] + ([] if seed is None else ["--seed", str(seed)])
        rc = main(["eval", "--config", str(config), "--data", str(data), "--workdir", str(work), *extra])
        if rc != 0:
            raise SystemExit(f"jaxmotion eval of {run} failed (exit status {rc})")
        total = time.perf_counter() - t0
        records = json.loads((work / "metrics.json").read_text())
    what = f"precision {precision}" + ("" if seed is None else f", sampling seed {seed}")
    print(f"\n(a) jaxmotion eval {run} ({what}): {records[0]['n_windows']} windows")
    for r in records:
        print(f"  {r['method']:<14s} K={r['K']}: {r['wall_s']:6.1f} s = compile {r['compile_s']:5.1f} s + run "
              f"{r['wall_s'] - r['compile_s']:6.1f} s | {_metrics_line(r['metrics'], ref.get((r['method'], r['K'])))}")
    wall = sum(r["wall_s"] for r in records)
    compile_s = sum(r["compile_s"] for r in records)
    print(f"  evaluation: {wall:.1f} s = compile {compile_s:.1f} s + run {wall - compile_s:.1f} s; "
          f"{_verdict(wall - compile_s)}")
    print(f"  whole command {total:.1f} s (also data loading, restoring, samples.png / samples.gif)")
    return records


def sampling_breakdown(run: Path, config: Path, ds, full, records: list[dict], precision: str = "float32") -> None:
    """Prints, per sampler of (a), the time its sampling alone takes, and so what the metrics take."""
    import dataclasses

    import jax

    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = dataclasses.replace(experiment.resolve(load_config(str(config))), precision=precision)
    params = experiment.restore(cfg, full, run)
    print("  where the time goes (sampling alone, once compiled; metrics = run - sampling):")
    for r in records:
        fn = experiment.predictors(cfg, ds, params, r["K"])[r["method"]]
        key = jax.random.key(cfg.seed + 7)
        next(experiment.predict_chunks(fn, full.x[: cfg.eval_batch], key, cfg.eval_batch))  # compiles
        t0 = time.perf_counter()
        for _ in experiment.predict_chunks(fn, full.x, key, cfg.eval_batch):
            pass
        sample_s = time.perf_counter() - t0
        run_s = r["wall_s"] - r["compile_s"]
        r["sampling_s"] = round(sample_s, 2)
        print(f"    {r['method']:<14s} sampling {sample_s:6.1f} s, metrics {run_s - sample_s:6.1f} s")


def k1000_target(run: Path, config: Path, ds, full, k: int, windows: int, methods: list[str], previous: dict | None,
                 precision: str = "float32") -> list[dict]:
    """Returns the K sweep rows at `k` for `methods`, after printing their timings (reference: `previous`'s rows)."""
    import dataclasses

    from experiments.divsamp_k_sweep import sweep_point
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = dataclasses.replace(load_config(str(config)), precision=precision)
    sub = experiment.prepare(ds, windows)
    params = experiment.restore(cfg, full, run)
    print(f"\n(b) DivSamp K sweep point {run} (precision {precision}): K = {k}, {len(sub.x)} of {len(full.x)} test windows, "
          "sampling included" + (f"; reference: {previous['what']}" if previous else ""))
    ref = {(r["run"], r["method"], r["K"], r["n_windows"]): r for r in (previous or {}).get("k_point", [])}
    rows = []
    for name in methods:
        r = {"run": str(run), "precision": precision, **sweep_point(cfg, ds, params, full, sub, name, k)}
        run_s = r["wall_s"] - r["compile_s"]
        print(f"  {name:<14s} K={k}: {r['wall_s']:6.1f} s = compile {r['compile_s']:5.1f} s + run {run_s:6.1f} s | "
              f"{_verdict(run_s)}\n    {_metrics_line(r, ref.get((r['run'], name, k, r['n_windows'])))}")
        rows.append(r)
    return rows


def _previous_k_point(out: Path) -> dict | None:
    """Returns the float32 K-point rows of the previous results file (either layout), as `{"what", "k_point"}`."""
    if not out.exists():
        return None
    prev = json.loads(out.read_text())
    rows = prev.get("by_precision", {}).get("float32", prev).get("k_point")
    return {"what": f"the previous eval_speed run's float32 figures ({prev['date']})", "k_point": rows} if rows else None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=("eval", "k1000"), help="run one part (default: both)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--dlow-run", type=Path, default=RUNS / "dlow_s0")
    ap.add_argument("--divsamp-run", type=Path, default=RUNS / "divsamp_s0")
    configs = ROOT / "experiments" / "configs"
    ap.add_argument("--dlow-config", type=Path, default=configs / "dlow_bandai.py",
                    help="the config the DLow run was trained with (another budget: the same evaluation)")
    ap.add_argument("--divsamp-config", type=Path, default=configs / "divsamp_bandai.py",
                    help="the config the DivSamp run was trained with")
    ap.add_argument("--k", type=int, default=1000, help="K of part (b)")
    ap.add_argument("--windows", type=int, default=200, help="test windows of part (b)")
    ap.add_argument("--methods", nargs="+", default=["divsamp"], help="predictors of part (b) (e.g. divsamp divsamp_cvae)")
    ap.add_argument("--no-breakdown", action="store_true", help="skip timing (a)'s sampling alone")
    ap.add_argument("--precision", nargs="+", choices=("float32", "bf16"), default=["float32"],
                    help="run both parts at each of these product precisions (Config.precision), in this order")
    ap.add_argument("--noise-seed", type=int, default=None, metavar="S",
                    help="also run (a) in float32 with sampling seed S: the metrics' change from the noise draws alone")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "eval_speed.json",
                    help="results file; (b)'s metric values are compared with the previous one's")
    ap.add_argument("--hugepages", choices=("on", "off"), default="on",
                    help="restart with glibc's huge-page tunable as the jaxmotion command does (jaxmotion/train/hugepages.py); "
                         "off: glibc's default pages")
    args = ap.parse_args(argv)
    from jaxmotion.train import hugepages

    if args.hugepages == "on":
        hugepages.exec_with_hugepages()
    elif hugepages.has_tunable(os.environ):
        raise SystemExit("eval_speed.py --hugepages off: GLIBC_TUNABLES holds the huge-page tunable; unset it first")
    import jax

    from jaxmotion import experiment
    from jaxmotion.config import load_config

    m = {**machine(), "bf16": has_bf16(cpu_flags()),
         "glibc_tunables": os.environ.get("GLIBC_TUNABLES", ""), "thp_mode": hugepages.thp_mode()}
    print(f"CPU: {m['cpu']}, {m['logical_cpus']} logical CPUs, {m['memory_gib']} GiB, bfloat16 instructions: "
          f"{'yes' if m['bf16'] else 'no'}; jax {jax.__version__}, devices {[str(d) for d in jax.devices()]}; "
          f"GLIBC_TUNABLES={m['glibc_tunables'] or '(unset)'}, transparent huge pages: {m['thp_mode']}")
    t0 = time.perf_counter()
    dlow_cfg = args.dlow_config
    part_a, part_b = args.only in (None, "eval"), args.only in (None, "k1000")
    ds = full = None
    if part_b or part_a and not args.no_breakdown:
        # Both configs read Bandai-Namco-2 with no data options: one load serves both.
        ds = experiment.load_data(load_config(str(dlow_cfg)), str(args.data))
        full = experiment.prepare(ds)
    previous = _previous_k_point(args.out) if part_b else None
    by_precision = {}
    for prec in args.precision:
        records, rows = [], []
        if part_a:
            records = eval_target(args.dlow_run, dlow_cfg, args.data, prec)
            if not args.no_breakdown:
                sampling_breakdown(args.dlow_run, dlow_cfg, ds, full, records, prec)
        if part_b:
            rows = k1000_target(args.divsamp_run, args.divsamp_config, ds, full, args.k, args.windows,
                                args.methods, previous, prec)
            if prec == "float32":  # the later precisions' reference: this run's float32 figures
                previous = {"what": "this run's float32 figures", "k_point": rows}
        by_precision[prec] = {"eval": records, "k_point": rows}
    noise = eval_target(args.dlow_run, dlow_cfg, args.data, "float32", args.noise_seed) if part_a and args.noise_seed is not None else None
    if len(by_precision) > 1 or noise:
        _summary(by_precision, noise)
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": m,
           "command": "python benchmarks/eval_speed.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "by_precision": by_precision, "noise_seed": args.noise_seed, "noise_eval": noise}
    print(f"\neval_speed: {time.perf_counter() - t0:.0f} s in all")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1, default=float))
    print(f"wrote {args.out}")


def _run_s(records: list[dict]) -> float:
    return sum(r["wall_s"] - r["compile_s"] for r in records)


def _summary(by_precision: dict, noise: list[dict] | None) -> None:
    """Prints each precision's run times beside float32's, and the metric changes beside the noise draws' own."""
    base = by_precision.get("float32", next(iter(by_precision.values())))
    print("\nsummary (run times once compiled; metric change = largest |difference| over APD, ADE, FDE, MMADE, MMFDE):")
    for prec, res in by_precision.items():
        parts = []
        if res["eval"]:
            parts.append(f"(a) {_run_s(res['eval']):.1f} s ({_run_s(base['eval']) / _run_s(res['eval']):.2f}x float32)")
        for r, b in zip(res["k_point"], base["k_point"]):
            parts.append(f"(b) {r['method']} {r['wall_s'] - r['compile_s']:.1f} s "
                         f"({(b['wall_s'] - b['compile_s']) / (r['wall_s'] - r['compile_s']):.2f}x float32)")
        print(f"  {prec:<8s} " + "; ".join(parts))
        if res is base:
            continue
        for r, b in zip(res["eval"], base["eval"]):
            d = {k: r["metrics"][k] - b["metrics"][k] for k in SHOWN}
            print(f"    (a) {r['method']:<14s} vs float32: " + " ".join(f"{k} {v:+.5f}" for k, v in d.items()))
        for r, b in zip(res["k_point"], base["k_point"]):
            print(f"    (b) {r['method']:<14s} vs float32: " + " ".join(f"{k} {r[k] - b[k]:+.5f}" for k in SHOWN))
    for r, b in zip(noise or [], base["eval"]):
        print(f"  noise draws alone, (a) {r['method']:<14s}: " + " ".join(f"{k} {r['metrics'][k] - b['metrics'][k]:+.5f}" for k in SHOWN))


if __name__ == "__main__":
    main()
