"""One results table from trained runs: per seed, and mean +- standard deviation over seeds.

    python experiments/results_table.py RUN_DIR [RUN_DIR ...] [--metrics APD ADE FDE MMADE MMFDE] [--json OUT]
    python experiments/results_table.py --headline RUN_DIR [RUN_DIR ...]

Each RUN_DIR holds the `metrics.json` that `jaxmotion run` / `jaxmotion eval` writes. Rows are
grouped by (config name, sampler, K); a group with several seeds gets one row per seed and a
"mean +- sd" row (sd over seeds, ddof 1). Prints a markdown table; `--json` also writes the
grouped figures. Runs without a metrics.json are listed as missing, not silently dropped.

`--headline` prints the README's cross-method table instead: per K, one row per sampler (every
method, each method's own CVAE from N(0, I), zero-velocity once), mean +- sd over the seeds given,
the validity columns (bone deformation, angle violations, pose-prior NLL) and mode recall where
any record has them, and each row's budget (config name) and training wall time (minutes, mean
over seeds, from the stages' log.jsonl).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

DEFAULT_METRICS = ("APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m")


def load_runs(run_dirs: list[str]) -> tuple[dict, list[str]]:
    """Returns `({(config, method, K): {seed: metrics}}, missing run dirs)`."""
    groups: dict = defaultdict(dict)
    missing = []
    for d in run_dirs:
        f = Path(d) / "metrics.json"
        if not f.is_file():
            missing.append(str(d))
            continue
        for rec in json.loads(f.read_text()):
            key = (rec["config"]["name"], rec["method"], int(rec["K"]))
            seed = int(rec.get("seed", rec["config"].get("seed", 0)))
            if seed in groups[key]:
                raise SystemExit(f"{f}: seed {seed} of {key} appears in two runs; pass each seed's run once")
            groups[key][seed] = rec["metrics"]
    return groups, missing


def table(groups: dict, metrics: tuple[str, ...]) -> tuple[str, dict]:
    """Returns `(markdown, summary)` with a row per seed and a mean +- sd row per group of several seeds."""
    head = "| config | sampler | K | seed | " + " | ".join(metrics) + " |"
    lines = [head, "|" + " --- |" * (4 + len(metrics))]
    summary = {}
    for (name, method, k), by_seed in sorted(groups.items()):
        seeds = sorted(by_seed)
        for s in seeds:
            vals = [by_seed[s].get(m, float("nan")) for m in metrics]
            lines.append(f"| {name} | {method} | {k} | {s} | " + " | ".join(f"{v:.4f}" for v in vals) + " |")
        arr = np.array([[by_seed[s].get(m, np.nan) for m in metrics] for s in seeds], float)
        mean = arr.mean(0)
        sd = arr.std(0, ddof=1) if len(seeds) > 1 else np.full(len(metrics), np.nan)
        summary[f"{name}/{method}/K{k}"] = {
            "seeds": seeds, "mean": dict(zip(metrics, mean.tolist())), "sd": dict(zip(metrics, sd.tolist())),
        }
        if len(seeds) > 1:
            cells = " | ".join(f"**{m_:.4f}** +- {s_:.4f}" for m_, s_ in zip(mean, sd))
            lines.append(f"| {name} | {method} | {k} | mean +- sd ({len(seeds)}) | {cells} |")
    return "\n".join(lines), summary


# Sampler names (`Method.predictors` keys) -> headline row labels, in the table's order.
LABELS = {
    "zero_velocity": "zero-velocity",
    "cvae": "DLow's CVAE, N(0, I)", "dlow": "DLow",
    "divsamp_cvae": "DivSamp's CVAE, N(0, I)", "divsamp": "DivSamp",
    "mojo_prior": "MOJO's CVAE, N(0, I)", "mojo": "MOJO", "mojo_proj": "MOJO + projection",
    "gsps": "GSPS", "motionmap": "MotionMap",
}
HEADLINE_EXTRA = ("bone_deformation", "angle_violation", "prior_nll", "mode_recall", "CMD", "FID")


def train_minutes(run: Path) -> float | None:
    """Returns the run's training wall time in minutes: over stages, the sum of each process's last `time_s`.

    `time_s` counts from the start of the process that trained the stage, so a stage resumed with
    `--resume` starts again near 0: where `time_s` falls from one record to the next, the segment
    before it is added (its steps after the last checkpoint, trained twice, are counted twice).
    """
    total, found = 0.0, False
    for log in run.glob("*/log.jsonl"):
        last = None
        for line in log.read_text().splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if "time_s" in rec:
                if last is not None and rec["time_s"] < last:
                    total += last  # a resumed process: the earlier one's time
                last = rec["time_s"]
        if last is not None:
            total, found = total + last, True
    return total / 60 if found else None


def headline(run_dirs: list[str], metrics: tuple[str, ...]) -> str:
    """Returns the cross-method markdown tables (one per K) described in the module docstring."""
    runs = []
    for d in run_dirs:
        f = Path(d) / "metrics.json"
        if f.is_file():
            runs.append((json.loads(f.read_text()), train_minutes(Path(d))))
    return headline_records(runs, metrics)


def headline_records(runs: list[tuple[list[dict], float | None]], metrics: tuple[str, ...]) -> str:
    """Returns the tables of `headline` for runs given as `(metrics.json records, training minutes or None)`."""
    # (K, MM ground truth, sampler) -> config -> seed -> metrics. Runs whose multimodal ground truth
    # differs (MotionMap's default takes it from the training windows) get tables of their own:
    # their MMADE / MMFDE are not comparable with the protocol's.
    rows: dict = defaultdict(lambda: defaultdict(dict))
    minutes: dict = defaultdict(list)
    for records, m in runs:
        for rec in records:
            seed = int(rec.get("seed", rec["config"].get("seed", 0)))
            rows[(int(rec["K"]), rec.get("mm_source", "test"), rec["method"])][rec["config"]["name"]][seed] = rec["metrics"]
        if m is not None:
            minutes[records[0]["config"]["name"]].append(m)
    extra = [m for m in HEADLINE_EXTRA if any(m in v for r in rows.values() for c in r.values() for v in c.values())]
    cols = list(metrics) + extra
    order = {name: i for i, name in enumerate(LABELS)}
    out = []
    for k, mm in sorted({(k, mm) for k, mm, _ in rows}, key=lambda km: (-km[0], km[1] != "test", km[1])):
        title = f"K = {k}" + ("" if mm == "test" else f", MM ground truth: {mm!r} (not comparable with the protocol's)")
        timed = bool(minutes)  # the "train min" column only where some run's logs gave its training time
        out += [title, "", "| sampler | budget (config) | seeds | " + ("train min | " if timed else "") + " | ".join(cols) + " |",
                "|" + " --- |" * (3 + timed + len(cols))]
        samplers = sorted((s for kk, m, s in rows if (kk, m) == (k, mm)), key=lambda s: (order.get(s, len(order)), s))
        for s in samplers:
            configs = rows[(k, mm, s)]
            for name in sorted(configs)[: 1 if s == "zero_velocity" else None]:  # zero-velocity is the same in every run
                by_seed = configs[name]
                arr = np.array([[by_seed[sd].get(m, np.nan) for m in cols] for sd in sorted(by_seed)], float)
                with np.errstate(all="ignore"), warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)  # a column no seed has: NaN, shown as "-"
                    mean = np.nanmean(arr, 0) if np.isfinite(arr).any() else arr[0]
                sd = arr.std(0, ddof=1) if len(arr) > 1 else None
                cells = [
                    "-" if not np.isfinite(mv) else f"{mv:.4f}" + ("" if sd is None or not np.isfinite(sv) else f" +- {sv:.4f}")
                    for mv, sv in zip(mean, sd if sd is not None else [np.nan] * len(cols))
                ]
                mins = minutes.get(name)
                wall = "-" if s == "zero_velocity" or not mins else f"{np.mean(mins):.0f}"
                seeds = ",".join(map(str, sorted(by_seed)))
                out.append(f"| {LABELS.get(s, s)} | {name} | {seeds} | " + (f"{wall} | " if timed else "") + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run directories (each with a metrics.json)")
    ap.add_argument("--metrics", nargs="+", default=list(DEFAULT_METRICS))
    ap.add_argument("--json", default=None, help="also write the grouped figures here")
    ap.add_argument("--headline", action="store_true", help="the README's cross-method table, one per K")
    args = ap.parse_args(argv)
    groups, missing = load_runs(args.runs)
    for m in missing:
        print(f"missing: {m} has no metrics.json (not finished?)", file=sys.stderr)
    if not groups:
        print("no finished run among the given directories", file=sys.stderr)
        return 1
    if args.headline:
        print(headline(args.runs, tuple(m for m in args.metrics if m not in ("ADE-m", "FDE-m")) + ("ADE-m",)))
        return 0
    md, summary = table(groups, tuple(args.metrics))
    print(md)
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
