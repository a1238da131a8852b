"""One results table from trained runs: per seed, and mean +- standard deviation over seeds.

    python experiments/results_table.py RUN_DIR [RUN_DIR ...] [--metrics APD ADE FDE MMADE MMFDE] [--json OUT]

Each RUN_DIR holds the `metrics.json` that `jaxmotion run` / `jaxmotion eval` writes. Rows are
grouped by (config name, sampler, K); a group with several seeds gets one row per seed and a
"mean +- sd" row (sd over seeds, ddof 1). Prints a markdown table; `--json` also writes the
grouped figures. Runs without a metrics.json are listed as missing, not silently dropped.
"""

from __future__ import annotations

import argparse
import json
import sys
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run directories (each with a metrics.json)")
    ap.add_argument("--metrics", nargs="+", default=list(DEFAULT_METRICS))
    ap.add_argument("--json", default=None, help="also write the grouped figures here")
    args = ap.parse_args(argv)
    groups, missing = load_runs(args.runs)
    for m in missing:
        print(f"missing: {m} has no metrics.json (not finished?)", file=sys.stderr)
    if not groups:
        print("no finished run among the given directories", file=sys.stderr)
        return 1
    md, summary = table(groups, tuple(args.metrics))
    print(md)
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
