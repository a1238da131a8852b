"""GSPS's validity ablation as a picture: end poses of K samples of one test window from each GSPS run.

    python experiments/gsps_ablation.py FULL_RUN [ABLATION_RUN ...] [--data PATH] [--window W] [--k 10]
        [--out experiments/results/gsps_ablation_bandai]

Each RUN is a trained GSPS work directory (e.g. `gsps_bandai.py`, `gsps_bandai_no_prior.py`,
`gsps_bandai_no_angle.py`, all at one budget and seed). One row per run: the true end pose, then the
end poses (frame +t_pred) of K samples drawn with the evaluation's key. Every pose is scored under
the FIRST run's angle bounds and pose prior (`validity.from_gsps_run`), so the rows are comparable:
a sample whose end pose leaves an angle bound is drawn in red, with its per-frame pose-prior NLL
(nats, over its whole future) under it. The row titles give the means over the K samples of this
window. The window is `--window` or the most multimodal test window (`experiment.most_multimodal`,
the one `samples.png` shows). `--out` writes OUT.png and OUT.json (per-sample figures). Numbers over
every test window come from `experiments/validity_table.py` (the same scores, all windows, K = 50).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from validity_table import load_run  # noqa: E402  (the same restore and data cache)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="trained GSPS run directories; the first one's bounds and prior score all")
    p.add_argument("--data", default=None, help="the dataset path (default: each run's own, from its predictor.json)")
    p.add_argument("--window", type=int, default=None, help="test window (default: the most multimodal one)")
    p.add_argument("--k", type=int, default=10, help="samples per run (default 10)")
    p.add_argument("--out", default="gsps_ablation", help="write OUT.png and OUT.json")
    args = p.parse_args(argv)
    if args.k < 1:
        p.error(f"--k must be at least 1, got {args.k}")

    import jax
    import jax.numpy as jnp

    from jaxmotion import experiment
    from jaxmotion.eval import validity
    from jaxmotion.models import gsps
    from jaxmotion.pictures.viz import draw_pose, frames_to_joints, view_axes

    cache, rows, v, window = {}, [], None, args.window
    for run in map(Path, args.runs):
        cfg, prep, params = load_run(run, args.data, None, cache)
        if cfg.method != "gsps":
            raise SystemExit(f"{run}: a {cfg.method!r} run; this script compares GSPS runs (validity_table.py scores any method)")
        ds = prep.dataset
        if v is None:
            v = validity.from_gsps_run(cfg, ds, params)
            if window is None:
                window = int(experiment.most_multimodal(prep, 1)[0])
            if not 0 <= window < len(prep.x):
                raise SystemExit(f"--window {window}: the data has {len(prep.x)} test windows")
            roles = gsps.angle_roles(v.names, v.parents)  # the scoring skeleton's, the same for every run
        try:
            validity.check_skeleton(v, ds.skeleton.names, ds.skeleton.parents, str(run))
        except ValueError as e:
            raise SystemExit(str(e)) from None
        fn = experiment.predictors(cfg, ds, params, args.k)["gsps"]
        pred = np.asarray(fn(jnp.asarray(prep.x[window : window + 1]), jax.random.key(cfg.seed + 7)))  # (1, K, t, D)
        scores = {key: np.asarray(a)[0] for key, a in validity.sample_validity(v, pred).items()}  # (K,) each
        end_bad = np.asarray(gsps.violation_fraction(jnp.asarray(pred[0, :, -1:]), roles, jnp.asarray(v.bounds))) > 0
        rows.append({"run": str(run), "config": cfg.name, "pred": pred[0], "x": prep.x[window], "y": prep.y[window],
                     "end_violates": end_bad, **scores})
        print(f"{cfg.name}: window {window}, K={args.k}: end poses outside a bound {int(end_bad.sum())}/{args.k}, "
              f"frames outside a bound {scores['angle_violation'].mean():.3f}, prior NLL {scores['prior_nll'].mean():.1f}",
              flush=True)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parents = v.parents
    xj = frames_to_joints(rows[0]["x"])
    up, across, _ = view_axes(np.concatenate([xj, frames_to_joints(rows[0]["y"])]))
    step = 1.3 * np.ptp(xj[..., across]) + 0.6
    fig, axes = plt.subplots(len(rows), 1, figsize=(1.45 * (args.k + 1) + 1, 2.7 * len(rows)), squeeze=False)
    for ax, r in zip(axes[:, 0], rows):
        gj, pj = frames_to_joints(r["y"]), frames_to_joints(r["pred"])
        top = np.max(gj[-1, :, up]) + 0.1

        def centred(pose):
            return pose - np.where(np.arange(3) == across, pose[:, across].mean(), 0.0)

        draw_pose(ax, centred(gj[-1]), parents, across, up, color="k", lw=2)
        ax.text(0, top, "truth", ha="center", fontsize=8)
        for i in range(args.k):
            bad = bool(r["end_violates"][i])
            draw_pose(ax, centred(pj[i, -1]), parents, across, up, dx=(i + 1.3) * step, color="tab:red" if bad else "tab:blue", lw=2)
            ax.text((i + 1.3) * step, top, f"NLL {r['prior_nll'][i]:.0f}", ha="center", fontsize=7, color="tab:red" if bad else "k")
        ax.set_title(f"{r['config']}: {int(r['end_violates'].sum())} of {args.k} end poses outside an angle bound (red); "
                     f"frames outside a bound {r['angle_violation'].mean():.1%}, prior NLL {r['prior_nll'].mean():.1f} nats/frame",
                     fontsize=9)  # fmt: skip
        ax.set_aspect("equal")
        ax.axis("off")
    fig.suptitle(f"GSPS end poses (frame +{rows[0]['pred'].shape[1]}), test window {window}; scored under "
                 f"{rows[0]['config']}'s angle bounds and pose prior", fontsize=10)  # fmt: skip
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out.with_suffix(".png"), dpi=90)
    plt.close(fig)
    out.with_suffix(".json").write_text(json.dumps({
        "window": window, "K": args.k, "scored_under": rows[0]["run"],
        "runs": [{k: (val.tolist() if isinstance(val, np.ndarray) and k not in ("pred", "x", "y") else val)
                  for k, val in r.items() if k not in ("pred", "x", "y")} for r in rows],
    }, indent=1))  # fmt: skip
    print(f"wrote {out.with_suffix('.png')} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
