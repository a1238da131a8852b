"""Trains the HumanEva-I table's runs one after another and keeps each finished run's results.

    python experiments/reproduce_humaneva.py --data PATH [--runs-dir ~/jaxmotion-runs/humaneva] \\
        [--lock /tmp/jaxmotion-heavy.lock] [--runs CONFIG:SEED ...] [--list]

Each run is `jaxmotion run --config experiments/configs/<config>.py --data PATH --seed <seed>` into
`--runs-dir/<config>_s<seed>`, in the order of `RUNS` (the table's rows at the release budgets, second
seeds before the longest runs; `--runs` names others, e.g. a diagnostic). A run whose
`<config>_s<seed>_metrics.json` is already in `--results` is skipped; a run whose folder exists goes on
from its last checkpoint (`--resume`). When a run ends, its `metrics.json`, learning curve
(`<config>_s<seed>_curve.json`) and picture (`<config>_s<seed>_curves.png`) are copied into `--results`,
the files the Results page is generated from (`docs/generate.py`). Stop it at any time (Ctrl-C) and run
the same command again to go on (`--list` prints the runs still to do, each started run's newest checkpoint
per stage and an unfinished stage's pace; `--snapshot DIR` keeps the learning curves of unfinished runs, whose
folders a replaced machine would lose): the whole table is about 45 hours on a 2-core CPU (the Benchmarks page,
"What reproduction costs").

The runs use the library of the checkout this script is in: run it from a clone frozen at one commit, so
that a run that spans several sittings is trained by one code, with `--results` pointing at the checkout
where the results are committed. `--lock FILE` holds that lock (`flock`) around each run, so that other
heavy jobs on the machine wait for it. HumanEva-I is licensed: read it from a path outside the repository.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import plot_curves  # noqa: E402  (a sibling script)

# The table's runs in order: DLow and MOJO's three variants at the release budget with two seeds (the
# second seeds of the cheap ones first; VAE+DCT, half an hour a seed, a third: its two seeds' FDE differ by 11%),
# the budget-reduced GSPS stand-in among them, the longest last. A run folder lives on the machine that trains it,
# so the runs that fit in one sitting (GSPS at a tenth, about 2 h on a 2-core Intel Xeon; a MOJO variant, about
# 3 h) go before DivSamp's full budget (about 17 h), which only a machine kept across sittings finishes.
RUNS: tuple[tuple[str, int], ...] = (
    ("dlow_humaneva", 0), ("dlow_humaneva", 1),
    ("mojo_vae_dct_humaneva", 0), ("mojo_vae_dct_humaneva", 1), ("mojo_vae_dct_humaneva", 2),
    ("mojo_vae_dct5_humaneva", 0), ("gsps_humaneva_10pct", 0), ("mojo_vae_dct20_humaneva", 0),
    ("mojo_vae_dct5_humaneva", 1), ("mojo_vae_dct20_humaneva", 1),
    ("diffusion_humaneva_5pct", 0), ("divsamp_humaneva", 0),
)


def parse_run(text: str) -> tuple[str, int]:
    """Returns `(config, seed)` from `CONFIG:SEED` (a config name of `experiments/configs/`, without `.py`)."""
    config, sep, seed = text.partition(":")
    config = config.removesuffix(".py").split("/")[-1]
    if not sep or not seed.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r}: expected CONFIG:SEED, e.g. dlow_humaneva:1")
    if not (ROOT / "experiments" / "configs" / f"{config}.py").is_file():
        raise argparse.ArgumentTypeError(f"{text!r}: no config experiments/configs/{config}.py")
    return config, int(seed)


def pending(runs: list[tuple[str, int]], results: Path) -> list[tuple[str, int]]:
    """Returns the runs whose metrics are not in `results` yet, in order."""
    return [(c, s) for c, s in runs if not (results / f"{c}_s{s}_metrics.json").is_file()]


def command(config: str, seed: int, data: Path, workdir: Path, lock: Path | None, host_devices: int | None = None) -> list[str]:
    """Returns the command that trains and evaluates one run (resuming when its folder exists)."""
    cmd = [sys.executable, "-m", "jaxmotion.cli", "run", "--config", str(ROOT / "experiments" / "configs" / f"{config}.py"),
           "--data", str(data), "--workdir", str(workdir), "--seed", str(seed)]
    if host_devices is not None:
        cmd += ["--host-devices", str(host_devices)]
    if workdir.is_dir() and any(workdir.iterdir()):
        cmd.append("--resume")
    return (["flock", str(lock)] if lock else []) + cmd


def step_seconds(log: Path) -> float | None:
    """Returns the seconds a step took in the newest training segment of a stage's `log.jsonl` (its step
    records' `time_s` restarts at each `--resume`): the median between consecutive records, or None with fewer
    than two records in that segment."""
    if not log.is_file():
        return None
    segment: list[tuple[int, float]] = []
    for rec in plot_curves.log_records(log):
        if rec.get("curve") or "time_s" not in rec or "step" not in rec:
            continue
        if segment and rec["time_s"] < segment[-1][1]:
            segment = []
        segment.append((rec["step"], rec["time_s"]))
    # The median over the segment's records, so that a pause (the run stopped for other work) or a curve
    # evaluation between two records does not count as the pace.
    paces = sorted((t1 - t0) / (s1 - s0) for (s0, t0), (s1, t1) in zip(segment, segment[1:]) if s1 > s0)
    return paces[len(paces) // 2] if paces else None


def progress(workdir: Path) -> str:
    """Returns how far a started run got: each stage's newest checkpoint against its steps, e.g. `cvae 7,500 / 7,500,
    q_k50 8,000 / 15,500 (0.65 s a step, about 1.4 h to go)` (stages in training order: fewer upstream stages first;
    an unfinished stage's pace from its newest training segment's log), and whether it was evaluated."""
    stages = []
    for manifest in workdir.glob("*/stage.json"):
        info = json.loads(manifest.read_text())
        ckpt = manifest.parent / "ckpt"
        steps = [int(p.name) for p in ckpt.iterdir() if p.name.isdigit()] if ckpt.is_dir() else []
        stages.append((len(info.get("upstream", {})), manifest.parent.name, max(steps, default=0), info["num_steps"]))
    parts = []
    for _, name, done, total in sorted(stages):
        parts.append(f"{name} {done:,} / {total:,}")
        pace = step_seconds(workdir / name / "log.jsonl") if done < total else None
        if pace is not None:
            parts[-1] += f" ({pace:.2f} s a step, about {pace * (total - done) / 3600:.1f} h to go)"
    if (workdir / "metrics.json").is_file():
        parts.append("evaluated")
    return ", ".join(parts) or "no checkpoint yet"


def write_curve(run: Path, out: Path, stem: str, about: str = "") -> list[Path]:
    """Writes a run's learning curve so far (`<stem>_curve.json`) and its picture (`<stem>_curves.png`) into
    `out`; returns the files written (none when its logs hold no curve point yet)."""
    curves = plot_curves.load_curves(run)
    if not curves:
        return []
    out.mkdir(parents=True, exist_ok=True)
    _, rec = plot_curves.curve_record(run, curves, about)
    (out / f"{stem}_curve.json").write_text(json.dumps(rec, indent=1) + "\n")
    plot_curves.plot([(stem, curves)], out / f"{stem}_curves.png")
    return [out / f"{stem}_curve.json", out / f"{stem}_curves.png"]


def collect(run: Path, results: Path) -> list[Path]:
    """Copies a finished run's metrics, learning curve and picture into `results`; returns the files written."""
    records = json.loads((run / "metrics.json").read_text())
    stem = f"{records[0]['config']['name']}_s{records[0]['seed']}"
    results.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(run / "metrics.json", results / f"{stem}_metrics.json")
    return [results / f"{stem}_metrics.json", *write_curve(run, results, stem)]


def snapshot(runs: list[tuple[str, int]], runs_dir: Path, out: Path) -> list[Path]:
    """Writes each started, unevaluated run's learning curve so far into `out` as `<config>_s<seed>_partial_curve.json`
    and `..._partial_curves.png`, its progress (`progress`) in the record's `run` line; returns the files written.

    A run's folder lives on the machine that trains it: this keeps what an unfinished run has measured when that
    machine may not be there for the next sitting."""
    written = []
    for config, seed in runs:
        run = runs_dir / f"{config}_s{seed}"
        if run.is_dir() and not (run / "metrics.json").is_file():
            written += write_curve(run, out, f"{config}_s{seed}_partial", f"unfinished: {progress(run)}")
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, help="VideoPose3D's data_3d_humaneva15.npz")
    ap.add_argument("--runs-dir", type=Path, default=Path.home() / "jaxmotion-runs" / "humaneva")
    ap.add_argument("--results", type=Path, default=ROOT / "experiments" / "results" / "humaneva",
                    help="where finished runs' metrics, curves and pictures go")
    ap.add_argument("--runs", nargs="+", type=parse_run, default=None, metavar="CONFIG:SEED",
                    help="these runs instead of the table's (default: RUNS)")
    ap.add_argument("--lock", type=Path, default=None, help="hold this file's lock (flock) around each run")
    ap.add_argument("--list", action="store_true",
                    help="print the runs still to do (a started run: each stage's newest checkpoint, an unfinished "
                         "stage's seconds a step and hours to go) and stop")
    ap.add_argument("--snapshot", type=Path, default=None, metavar="DIR",
                    help="write each started, unfinished run's learning curve so far into DIR "
                         "(<config>_s<seed>_partial_curve.json and _curves.png, its progress in the record) and stop")
    ap.add_argument("--host-devices", type=int, default=None, metavar="N",
                    help="train runs on N CPU host devices (jaxmotion run --host-devices; the benchmarks page's "
                         "cost table says which stages it speeds up)")
    ap.add_argument("--host-devices-configs", nargs="+", default=None, metavar="CONFIG",
                    help="only these configs' runs on --host-devices (default: every run)")
    args = ap.parse_args(argv)
    todo = pending(list(args.runs or RUNS), args.results)
    if args.snapshot is not None:
        written = snapshot(todo, args.runs_dir, args.snapshot)
        print("\n".join(f"  {p}" for p in written) or f"no started, unfinished run with a curve point in {args.runs_dir}")
        return 0
    if args.list or not todo:
        print("\n".join(f"{c}:{s}" + (f" (started: {progress(d)})" if (d := args.runs_dir / f"{c}_s{s}").is_dir() else "")
                        for c, s in todo)
              or f"every run has its metrics in {args.results}")
        return 0
    if args.data is None or not args.data.is_file():
        ap.error(f"--data: {args.data} is not a file (VideoPose3D's data_3d_humaneva15.npz)")
    if args.host_devices is not None and args.host_devices < 1:
        ap.error(f"--host-devices: expected a count >= 1, got {args.host_devices}")
    unknown = sorted(set(args.host_devices_configs or ()) - {c for c, _ in todo})
    if unknown:
        ap.error(f"--host-devices-configs: {', '.join(unknown)} not among the runs to do ({', '.join(dict.fromkeys(c for c, _ in todo))})")
    if args.lock and not shutil.which("flock"):
        ap.error("--lock needs the flock command (util-linux)")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    for i, (config, seed) in enumerate(todo, 1):
        workdir = args.runs_dir / f"{config}_s{seed}"
        log = args.runs_dir / f"{config}_s{seed}.out"
        if not (workdir / "metrics.json").is_file():
            on_host = args.host_devices_configs is None or config in args.host_devices_configs
            cmd = command(config, seed, args.data, workdir, args.lock, args.host_devices if on_host else None)
            print(f"[{i}/{len(todo)}] {config} seed {seed}{' (resuming)' if '--resume' in cmd else ''}: progress in {log}",
                  flush=True)
            args.runs_dir.mkdir(parents=True, exist_ok=True)
            try:
                with open(log, "a") as out:
                    rc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=ROOT).returncode
            except KeyboardInterrupt:
                print(f"stopped during {config} seed {seed}: run the same command to go on from its last checkpoint",
                      file=sys.stderr)
                return 130
            if rc != 0:
                print(f"{config} seed {seed} failed (exit status {rc}): see the end of {log}", file=sys.stderr)
                return 1
        for p in collect(workdir, args.results):
            print(f"  {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
