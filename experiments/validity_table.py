"""Pose validity of every trained run's predictions under one GSPS run's angle bounds and pose prior.

    python experiments/validity_table.py RUN [RUN ...] --gsps-run GSPS_RUN [--data PATH] [--k 50]
        [--max-windows N] [--samplers NAME ...] [--out experiments/results/validity_bandai]

Each RUN is a trained work directory of any method (its `predictor.json` holds the config). The
script restores it (`experiment.restore`), draws K futures of the protocol test windows (all of
them, or `--max-windows` evenly spaced) with every sampler the run has at K, with the evaluation's
key, and prints per run and sampler: BDF (bone deformation, `realism.bone_deformation`), the
fraction of predicted frames outside an angle bound, and the mean pose-prior NLL per frame under the
GSPS run's flow prior (nats; also without the log-determinant, the release's `eval.py` figure),
beside APD / ADE / FDE / MMADE / MMFDE from the run's metrics.json (computed there on its own
`n_windows`), and CMD / FID (`jaxmotion.eval.action_metrics`: the project's own action classifier, trained
once per dataset and cached) on the same futures where the data has action labels (`--no-action-metrics`
leaves them out). A "ground truth" row scores the test windows' true futures. Every run must share the
GSPS run's skeleton. `--out` writes OUT.md and OUT.json (with the bounds used).

The data is the run's own (`--data` overrides the path in its predictor.json, e.g. when it was a
relative path). Cost: K x windows futures per sampler; on 2 CPU cores the 1,609 Bandai-Namco-2 test
windows at K = 50 take about a minute per sampler (run it under the heavy lock).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

PROTOCOL_COLUMNS = ("APD", "ADE", "FDE", "MMADE", "MMFDE")
VALIDITY_COLUMNS = ("BDF", "angle_violation", "prior_nll", "prior_nll_z")
ACTION_COLUMNS = ("CMD", "FID")
HEADERS = {"angle_violation": "angle viol.", "prior_nll": "prior NLL", "prior_nll_z": "NLL w/o log-det"}


def load_run(run: Path, data: str | None, max_windows: int | None, cache: dict):
    """Returns `(cfg, prep, params)` of a trained run directory, its data loaded once per (source, options, seed)."""
    from jaxmotion import experiment
    from jaxmotion.tools.predictor import run_config

    try:
        cfg, source = run_config(run)
    except FileNotFoundError as e:
        raise SystemExit(str(e)) from None
    cfg = experiment.resolve(cfg)
    spec = data or source
    key = (spec, json.dumps(cfg.data_options, sort_keys=True), cfg.seed if spec == "synthetic" else None, cfg.train_sampler)
    if key not in cache:
        ds = experiment.load_data(cfg, spec)
        cache[key] = experiment.prepare(ds, max_windows, cfg.train_sampler)
    prep = cache[key]
    return cfg, prep, experiment.restore(cfg, prep, run)


def protocol_metrics(run: Path, sampler: str, k: int) -> tuple[dict, int | None]:
    """Returns `(metrics, n_windows)` of `sampler` at K in the run's metrics.json (`({}, None)` when absent)."""
    f = run / "metrics.json"
    if f.is_file():
        for rec in json.loads(f.read_text()):
            if rec["method"] == sampler and int(rec["K"]) == k:
                return rec["metrics"], int(rec["n_windows"])
    return {}, None


def score(v, chunks, action=None) -> dict[str, float]:
    """Returns the validity metrics averaged over the windows of `chunks` (each `(b, K, t_pred, D)`), one pass.

    With an `action_metrics.ActionEvaluator`, also CMD and FID of the same futures (the chunks must
    cover every test window, in order).
    """
    from jaxmotion.eval import validity

    parts, action_parts = [], []
    for p in chunks:
        parts.append(validity.window_validity(v, p))
        if action is not None:
            action_parts.append(action.chunk(p))
    out = {key: float(np.mean(np.concatenate([p[key] for p in parts]))) for key in parts[0]}
    return {**out, **(action.result(action_parts) if action is not None else {})}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="trained run directories (any method)")
    p.add_argument("--gsps-run", required=True, help="a trained GSPS run: its angle bounds and pose prior score every run")
    p.add_argument("--data", default=None, help="the dataset path (default: each run's own, from its predictor.json)")
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--max-windows", type=int, default=None, help="evenly spaced test windows (default: every protocol window)")
    p.add_argument("--samplers", nargs="+", default=None, help="only these samplers (default: every sampler of every run)")
    p.add_argument("--out", default=None, help="write OUT.md and OUT.json")
    p.add_argument("--no-action-metrics", dest="action_metrics", action="store_false",
                   help="leave out CMD and FID (they need the data's action labels and a trained classifier)")
    args = p.parse_args(argv)

    import jax

    from jaxmotion import experiment
    from jaxmotion.eval import validity
    from jaxmotion.errors import CheckpointError
    from jaxmotion.tools.predictor import load

    # Only the prior and the bounds are read: a GSPS run stopped once its generator stage began scores too.
    try:
        g = load(args.gsps_run, stages=("prior", "angle_bounds"))
    except (FileNotFoundError, CheckpointError) as e:
        raise SystemExit(f"--gsps-run: {e}") from None
    if g.config.method != "gsps":
        raise SystemExit(f"--gsps-run {args.gsps_run}: a {g.config.method!r} run, not a GSPS run")
    v = validity.from_gsps_run(g.config, g.dataset, g.params)
    rows, cache, actions = [], {}, {}
    for run in map(Path, args.runs):
        cfg, prep, params = load_run(run, args.data, args.max_windows, cache)
        ds = prep.dataset
        try:
            validity.check_skeleton(v, ds.skeleton.names, ds.skeleton.parents, str(run))
        except ValueError as e:
            raise SystemExit(str(e)) from None
        if id(prep) not in actions:  # the classifier and the true futures, once per dataset
            from jaxmotion.eval.loop import action_evaluator

            actions[id(prep)] = action = action_evaluator(cfg, prep) if args.action_metrics else None
            gt = [prep.y[s : s + cfg.eval_batch, None] for s in range(0, len(prep.y), cfg.eval_batch)]
            rows.append({"run": ds.name, "sampler": "ground truth", "K": 1, "n_windows": len(prep.windows),
                         **score(v, gt, action)})
        action = actions[id(prep)]
        try:
            fns = experiment.predictors(cfg, ds, params, args.k)
        except KeyError as e:
            raise SystemExit(f"{run}: stage {e.args[0]!r} is not trained") from None
        for name, fn in fns.items():
            if args.samplers and name not in args.samplers:
                continue
            chunks = experiment.predict_chunks(fn, prep.x, jax.random.key(cfg.seed + 7), cfg.eval_batch)
            m, n_eval = protocol_metrics(run, name, args.k)
            rows.append({"run": str(run), "config": cfg.name, "sampler": name, "K": args.k, "n_windows": len(prep.windows),
                         "metrics_json_windows": n_eval, **{c: m.get(c) for c in PROTOCOL_COLUMNS}, **score(v, chunks, action)})
            print(f"{run} {name}: " + " ".join(f"{c}={rows[-1][c]:.4f}" for c in VALIDITY_COLUMNS + ACTION_COLUMNS if c in rows[-1]),
                  file=sys.stderr, flush=True)

    cols = PROTOCOL_COLUMNS + VALIDITY_COLUMNS + tuple(c for c in ACTION_COLUMNS if any(c in r for r in rows))
    lines = ["| run | sampler | K | windows (here / metrics.json) | " + " | ".join(HEADERS.get(c, c) for c in cols) + " |",
             "|" + " --- |" * (4 + len(cols))]
    for r in rows:
        cells = [f"{r[c]:.4f}" if r.get(c) is not None else "-" for c in cols]
        n = f"{r['n_windows']} / {r.get('metrics_json_windows') or '-'}"
        lines.append(f"| {r['run']} | {r['sampler']} | {r['K']} | {n} | " + " | ".join(cells) + " |")
    md = "\n".join(lines)
    print(md)
    print(f"\nangle bounds and pose prior: {args.gsps_run} ({g.config.name}); APD..MMFDE: each run's metrics.json; "
          f"angle viol.: fraction of predicted frames outside a bound; prior NLL: nats per frame"
          + ("; CMD / FID: the project's own action classifier, on these futures" if "CMD" in cols else ""))
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".md").write_text(md + "\n")
        out.with_suffix(".json").write_text(json.dumps(
            {"gsps_run": str(args.gsps_run), "K": args.k, "max_windows": args.max_windows,
             "angle_bounds": validity.bounds_record(v.bounds), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
