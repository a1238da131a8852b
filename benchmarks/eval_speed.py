"""Evaluation speed on Bandai-Namco-2, against issue 18's two targets: compile time and run time apart, metric values shown.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/eval_speed.py      # both targets (quiet machine: about 3 minutes)
    python benchmarks/eval_speed.py --only eval                          # (a) alone
    python benchmarks/eval_speed.py --only k1000                         # (b) alone

(a) `jaxmotion eval` of the DLow run (config experiments/configs/dlow_bandai.py; 1,609 test windows,
    K = 50, three samplers: zero-velocity, the CVAE from N(0, I), DLow), run through the command
    itself on a copy of the run folder in a temporary directory (the command writes metrics.json
    and pictures there). Target: the evaluation under 30 s once compiled, i.e. the sum over the
    samplers of their records' `wall_s - compile_s`.
(b) The K = 1000 point of `experiments/divsamp_k_sweep.py` (DivSamp, 200 evenly spaced test windows,
    sampling included, MM sets over all test windows). Target: under 30 s once compiled.

Each part prints the CPU model, the time spent compiling (jax's own compile events,
`jaxmotion.compile_time`) and the rest, and the metric values beside a reference (for (a) the run's
own metrics.json, for (b) the previous run of this script, `--out`), so a speed-up that changes the
numbers shows; (a) also times each sampler's sampling alone, to say where the time goes. The run
folders are only read. Timings mean something only on a quiet machine (hence the lock).
"""

from __future__ import annotations

import argparse
import datetime
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine  # noqa: E402

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


def eval_target(run: Path, config: Path, data: Path) -> list[dict]:
    """Returns the records (metrics.json) of `jaxmotion eval` on a copy of `run`, after printing their timings."""
    from jaxmotion.cli import main

    ref = {(r["method"], r["K"]): r["metrics"] for r in json.loads((run / "metrics.json").read_text())}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp) / run.name
        shutil.copytree(run, work, ignore=shutil.ignore_patterns("*.png", "*.gif", "metrics.json"))
        t0 = time.perf_counter()
        assert main(["eval", "--config", str(config), "--data", str(data), "--workdir", str(work)]) == 0
        total = time.perf_counter() - t0
        records = json.loads((work / "metrics.json").read_text())
    print(f"\n(a) jaxmotion eval {run}: {records[0]['n_windows']} windows")
    for r in records:
        print(f"  {r['method']:<14s} K={r['K']}: {r['wall_s']:6.1f} s = compile {r['compile_s']:5.1f} s + run "
              f"{r['wall_s'] - r['compile_s']:6.1f} s | {_metrics_line(r['metrics'], ref.get((r['method'], r['K'])))}")
    wall = sum(r["wall_s"] for r in records)
    compile_s = sum(r["compile_s"] for r in records)
    print(f"  evaluation: {wall:.1f} s = compile {compile_s:.1f} s + run {wall - compile_s:.1f} s; "
          f"{_verdict(wall - compile_s)}")
    print(f"  whole command {total:.1f} s (also data loading, restoring, samples.png / samples.gif)")
    return records


def sampling_breakdown(run: Path, config: Path, ds, full, records: list[dict]) -> None:
    """Prints, per sampler of (a), the time its sampling alone takes, and so what the metrics take."""
    import jax

    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = experiment.resolve(load_config(str(config)))
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
        print(f"    {r['method']:<14s} sampling {sample_s:6.1f} s, metrics {run_s - sample_s:6.1f} s")


def k1000_target(run: Path, config: Path, ds, full, k: int, windows: int, methods: list[str], previous: dict | None) -> list[dict]:
    """Returns the K sweep rows at `k` for `methods`, after printing their timings."""
    from experiments.divsamp_k_sweep import sweep_point
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = load_config(str(config))
    sub = experiment.prepare(ds, windows)
    params = experiment.restore(cfg, full, run)
    print(f"\n(b) DivSamp K sweep point {run}: K = {k}, {len(sub.x)} of {len(full.x)} test windows, sampling included"
          + (f"; reference: the previous eval_speed run ({previous['date']})" if previous else ""))
    ref = {(r["run"], r["method"], r["K"], r["n_windows"]): r for r in (previous or {}).get("k_point", [])}
    rows = []
    for name in methods:
        r = {"run": str(run), **sweep_point(cfg, ds, params, full, sub, name, k)}
        run_s = r["wall_s"] - r["compile_s"]
        print(f"  {name:<14s} K={k}: {r['wall_s']:6.1f} s = compile {r['compile_s']:5.1f} s + run {run_s:6.1f} s | "
              f"{_verdict(run_s)}\n    {_metrics_line(r, ref.get((r['run'], name, k, r['n_windows'])))}")
        rows.append(r)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=("eval", "k1000"), help="run one part (default: both)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--dlow-run", type=Path, default=RUNS / "dlow_s0")
    ap.add_argument("--divsamp-run", type=Path, default=RUNS / "divsamp_s0")
    ap.add_argument("--k", type=int, default=1000, help="K of part (b)")
    ap.add_argument("--windows", type=int, default=200, help="test windows of part (b)")
    ap.add_argument("--methods", nargs="+", default=["divsamp"], help="predictors of part (b) (e.g. divsamp divsamp_cvae)")
    ap.add_argument("--no-breakdown", action="store_true", help="skip timing (a)'s sampling alone")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "eval_speed.json",
                    help="results file; (b)'s metric values are compared with the previous one's")
    args = ap.parse_args(argv)
    import jax

    from jaxmotion import experiment
    from jaxmotion.config import load_config

    m = machine()
    print(f"CPU: {m['cpu']}, {m['logical_cpus']} logical CPUs, {m['memory_gib']} GiB; jax {jax.__version__}, "
          f"devices {[str(d) for d in jax.devices()]}")
    t0 = time.perf_counter()
    configs = ROOT / "experiments" / "configs"
    records = eval_target(args.dlow_run, configs / "dlow_bandai.py", args.data) if args.only in (None, "eval") else []
    if records and not args.no_breakdown or args.only in (None, "k1000"):
        # Both configs read Bandai-Namco-2 with no data options: one load serves both.
        ds = experiment.load_data(load_config(str(configs / "dlow_bandai.py")), str(args.data))
        full = experiment.prepare(ds)
    if records and not args.no_breakdown:
        sampling_breakdown(args.dlow_run, configs / "dlow_bandai.py", ds, full, records)
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": m,
           "command": "python benchmarks/eval_speed.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "eval": records}
    if args.only in (None, "k1000"):
        previous = json.loads(args.out.read_text()) if args.out.exists() else None
        doc["k_point"] = k1000_target(args.divsamp_run, configs / "divsamp_bandai.py", ds, full, args.k, args.windows,
                                      args.methods, previous)
    print(f"\neval_speed: {time.perf_counter() - t0:.0f} s in all")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1, default=float))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
