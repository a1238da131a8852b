"""Learning curves of trained runs: APD, ADE, FDE and MMADE over training steps, one PNG per run.

    python experiments/plot_curves.py RUN_DIR [RUN_DIR ...] [--out-dir DIR] [--tail 0.2]
    python experiments/plot_curves.py A_curve.json B_curve.json --overlay OUT.png   # kept curves, compared

A run trained with `Config.curve_every > 0` has learning-curve lines (`"curve": true`) in each
stage's `log.jsonl` (`jaxmotion.eval.learning_curve`). Per run this writes `curves.png`
(into the run folder, or `--out-dir/<run name>_curves.png`): one row per stage, one column per
metric, one line per predictor, and prints, per stage and predictor, each metric's first, best and
last value and its relative change over the last `--tail` of the stage's steps: the "flattened?"
figure (a metric that still moves by several percent over the last fifth has not converged).
Several runs (seeds of one config, or two settings) are drawn into one figure with `--overlay OUT.png`,
one colour per run. `--json-dir DIR` also writes each run's points as `DIR/<config name>_s<seed>_curve.json`
(`{"run": ..., "curve": [{stage, step, predictor, APD, ADE, ...}, ...]}`), the form kept beside a
long run's `metrics.json` in `experiments/results/long/`; `--about TEXT` adds how the run was made.
Such a file is read wherever a run folder is, so kept curves are drawn after their run folder is gone
(points without a `predictor` are named by the file's first word, e.g. `gsps`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

METRICS = ("APD", "ADE", "FDE", "MMADE")
STYLES = ("-", "--", ":", "-.")


def log_records(log: Path):
    """Yields the records of a stage's `log.jsonl`, skipping a line a kill cut short."""
    for line in log.read_text().splitlines():
        try:
            yield json.loads(line)
        except ValueError:
            continue


def load_curves(run: Path) -> dict[str, dict[str, list[tuple[int, dict]]]]:
    """Returns `{stage folder: {predictor: [(step, metrics), ...]}}` from a run's stage logs (or from a
    `*_curve.json` file that `--json-dir` wrote), in step order."""
    out: dict = {}
    if run.is_file():
        for p in json.loads(run.read_text())["curve"]:
            m = {k: v for k, v in p.items() if k not in ("stage", "step", "predictor")}
            out.setdefault(p["stage"], {}).setdefault(p.get("predictor", run.name.split("_")[0]), []).append((int(p["step"]), m))
        return {stage: {k: sorted(v, key=lambda t: t[0]) for k, v in preds.items()} for stage, preds in out.items()}
    for log in sorted(run.glob("*/log.jsonl")):
        by_pred: dict = {}
        for rec in log_records(log):
            if not rec.get("curve"):
                continue
            for name, m in rec["predictors"].items():
                by_pred.setdefault(name, []).append((int(rec["step"]), m))
        if by_pred:
            out[log.parent.name] = {k: sorted(v, key=lambda t: t[0]) for k, v in by_pred.items()}
    return out


def tail_change(points: list[tuple[int, dict]], metric: str, tail: float) -> float | None:
    """Returns `(last - value at the start of the last `tail` of steps) / |last|` (None with under 2 points there)."""
    last_step = points[-1][0]
    cut = last_step * (1 - tail)
    early = [m[metric] for s, m in points if s <= cut]
    if not early or len(points) < 2:
        return None
    ref, last = early[-1], points[-1][1][metric]
    return (last - ref) / abs(last) if last else None


def summary(curves: dict, tail: float) -> list[str]:
    """Returns one text line per (stage, predictor, metric): first, best, last and the tail change."""
    lines = []
    for stage, preds in curves.items():
        for name, pts in preds.items():
            for m in METRICS:
                vals = [p[m] for _, p in pts]
                best = max(vals) if m == "APD" else min(vals)
                ch = tail_change(pts, m, tail)
                chs = "n/a" if ch is None else f"{100 * ch:+.1f}%"
                lines.append(
                    f"{stage:>12} {name:>14} {m:>6}: step {pts[0][0]}->{pts[-1][0]} first {vals[0]:.4f} best {best:.4f} "
                    f"last {vals[-1]:.4f}; last {int(100 * tail)}% of steps {chs}"
                )
    return lines


def curve_record(run: Path, curves: dict, about: str = "") -> tuple[str, dict]:
    """Returns `(file name, {"run": ..., "curve": [...]})` for a run's curves, named by its config and seed."""
    from jaxmotion.tools.predictor import run_config  # only here: drawing curves needs no jax

    try:
        cfg = run_config(run)[0]
        name, seed = cfg.name, cfg.seed
    except FileNotFoundError:  # neither a manifest nor records: the folder's name
        name, seed = run.name, None
    stem = f"{name}_s{seed}" if seed is not None else name
    desc = f"experiments/configs/{name}.py" + (f", seed {seed}" if seed is not None else "") + (f"; {about}" if about else "")
    points = [{"stage": stage, "step": step, "predictor": pred, **m}
              for stage, preds in curves.items() for pred, pts in preds.items() for step, m in pts]
    return f"{stem}_curve.json", {"run": desc, "curve": points}


def plot(runs: list[tuple[str, dict]], out: Path) -> None:
    """Draws the curves of one or more runs (same stages) into `out`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = list(dict.fromkeys(s for _, c in runs for s in c))
    fig, axes = plt.subplots(len(stages), len(METRICS), figsize=(4 * len(METRICS), 3 * len(stages)), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    preds = list(dict.fromkeys(p for _, c in runs for s in c.values() for p in s))
    labels = [label for label, _ in runs]
    for r, stage in enumerate(stages):
        for c, m in enumerate(METRICS):
            ax = axes[r, c]
            for label, curves in runs:
                for name, pts in curves.get(stage, {}).items():
                    # One run: a colour per predictor. Several: a colour per run, a line style per predictor.
                    tag = name if len(runs) == 1 else f"{name} {label}"
                    color = colors[(preds.index(name) if len(runs) == 1 else labels.index(label)) % len(colors)]
                    ax.plot([s for s, _ in pts], [p[m] for _, p in pts], marker=".", color=color, label=tag,
                            linestyle="-" if len(runs) == 1 else STYLES[preds.index(name) % len(STYLES)])
            # The untrained step-0 point would flatten the rest of the curve: the y-range is that of the later points.
            later = [p[m] for _, c in runs for pts in c.get(stage, {}).values() for s, p in pts if s > 0]
            if later:
                lo, hi = min(later), max(later)
                pad = 0.08 * (hi - lo) or 0.05 * abs(hi) or 0.05
                ax.set_ylim(lo - pad, hi + pad)
            ax.set_title(f"{stage}: {m}" + (" (step 0 may be off the scale)" if later else ""), fontsize=9)
            ax.set_xlabel("step")
            ax.grid(alpha=0.3)
            if c == 0:
                ax.legend(fontsize=7)
    fig.suptitle(", ".join(label for label, _ in runs) + " (metres; fixed test-window subset)", fontsize=10)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run folders or *_curve.json files")
    ap.add_argument("--out-dir", type=Path, default=None)
    ap.add_argument("--overlay", type=Path, default=None, help="one figure of every run, a colour per run")
    ap.add_argument("--tail", type=float, default=0.2)
    ap.add_argument("--json-dir", type=Path, default=None, help="also write <config>_s<seed>_curve.json files here")
    ap.add_argument("--about", default="", help="how the runs were made, kept in the JSON files")
    args = ap.parse_args(argv)
    loaded, missing = [], []
    for run in args.runs:
        try:
            curves = load_curves(run)
        except (ValueError, KeyError, TypeError) as e:  # a file that is not a `--json-dir` curve file
            print(f"{run}: not a learning-curve file ({type(e).__name__}: {e})", file=sys.stderr)
            missing.append(str(run))
            continue
        if not curves:
            missing.append(str(run))
            continue
        name = run.name.removesuffix("_curve.json") if run.is_file() else run.name
        loaded.append((name, curves))
        # A kept curve file gets a figure of its own only with --out-dir (never one beside the file).
        out = (args.out_dir / f"{name}_curves.png") if args.out_dir else None if run.is_file() else run / "curves.png"
        if out is not None:
            plot([(name, curves)], out)
            print(f"# {run}: {out}")
        if args.json_dir and not run.is_file():
            fname, rec = curve_record(run, curves, args.about)
            args.json_dir.mkdir(parents=True, exist_ok=True)
            (args.json_dir / fname).write_text(json.dumps(rec, indent=1) + "\n")
            print(f"# {run}: {args.json_dir / fname}")
        print("\n".join(summary(curves, args.tail)))
    if args.overlay and loaded:
        plot(loaded, args.overlay)
        print(f"# overlay: {args.overlay}")
    if missing:
        print(f"no learning-curve lines (train with Config.curve_every > 0) in: {', '.join(missing)}", file=sys.stderr)
    return 1 if not loaded else 0


if __name__ == "__main__":
    sys.exit(main())
