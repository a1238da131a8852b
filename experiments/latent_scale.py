"""Diversity against accuracy of a trained CVAE when its latents are drawn from N(0, s^2 I), s below and above 1.

    python experiments/latent_scale.py --config experiments/configs/mojo_vae_dct_humaneva.py \
        --data data_3d_humaneva15.npz --workdir RUN_DIR --scales 0.25,0.5,0.75,1 --out OUT.json [--plot OUT.png] \
        [--sampler q]

A diagnostic, not a setting: the library's CVAE sampler draws N(0, I) (s = 1) and nothing here changes
that. The curve answers one question of a results row whose diversity (APD) differs from a paper's:
at the paper's APD, are this library's best-of-K errors the paper's? Best-of-K errors fall as the
K futures spread (a wider set holds a closer one), so a row that is more diverse than the paper's is
expected to be more accurate too; the curve measures by how much. Every point is the full evaluation
(`jaxmotion.eval.loop.evaluate`: the same test windows, multimodal sets and noise key as `jaxmotion eval`),
with the run's CVAE decoding `s * z` for the same draws `z`.

`--sampler q` asks the same of a trained second stage (MOJO's VAE+DCT+L: DLow on the lowest L bands): the K
latents the Q network gives each window on those bands are spread about their mean by s (`mean + s (z_k - mean)`;
the bands above, N(0, I), as drawn), so s = 1 is the run's own "mojo" sampler and s > 1 reaches the diversity of a
row more diverse than ours.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp

from jaxmotion import experiment
from jaxmotion.config import load_config
from jaxmotion.eval import loop as eval_loop
from jaxmotion.methods import get_method
from jaxmotion.methods.common import execution_of
from jaxmotion.models import dlow, mojo
from jaxmotion.models.cvae import decode_k
from jaxmotion.nn.batch import batch_rows

# method -> (its CVAE module, its CVAE settings from the method's settings)
CVAES = {"dlow": (dlow, lambda m: m.cvae), "mojo": (mojo, lambda m: m)}
METRICS = ("APD", "ADE", "FDE", "MMADE", "MMFDE")


def scaled_prior(model, params, k: int, s: float):
    """Returns a jitted `(x, key) -> (b, K, t_pred, D)` sampler decoding `s * z`, `z` the CVAE sampler's own N(0, I) draws."""

    def fn(x, key):
        z = batch_rows(lambda n: jax.random.normal(key, (n, k) + model.latent_shape), x.shape[0])
        return decode_k(model, params, x, s * z)

    return jax.jit(fn)


def scaled_q(model, params, q, q_params, s: float):
    """Returns a jitted `(x, key) -> (b, K, t_pred, D)` sampler: MOJO's second stage (`mojo.sample_mojo`) with the Q
    network's K latents on its lowest bands spread about their mean by `s`; the bands above as drawn."""

    def fn(x, key):
        z, _, _ = mojo.q_latents(model, q, q_params, x, key)
        low = z[:, :, : q.n_low]
        mean = jnp.mean(low, axis=1, keepdims=True)
        return decode_k(model, params, x, z.at[:, :, : q.n_low].set(mean + s * (low - mean)))

    return jax.jit(fn)


def sweep(cfg, prep, params, scales: list[float], sampler: str = "prior") -> list[dict]:
    """Returns one record per scale: `{"scale", "K", "metrics": {APD, ADE, FDE, MMADE, MMFDE}}` at the config's largest K.

    `sampler`: "prior" scales the CVAE's N(0, I) draws; "q" spreads MOJO's Q latents (`scaled_q`).
    """
    method = get_method(cfg.method)
    if cfg.method not in CVAES:
        raise SystemExit(f"--config: method {cfg.method!r} has no CVAE prior sampler here (one of {sorted(CVAES)})")
    module, settings = CVAES[cfg.method]
    cvae_cfg = settings(method.settings(cfg))
    model = module.cvae_model(cvae_cfg, prep.dataset.dim, prep.dataset.t_pred, execution_of(cfg))
    k = max(cfg.eval_k)
    if sampler == "q":
        if cfg.method != "mojo" or f"q_k{k}" not in params:
            raise SystemExit(f"--sampler q: needs a MOJO run with a trained second stage q_k{k} (this run: method "
                             f"{cfg.method!r}, stages {sorted(params)})")
        q = mojo.q_model(cvae_cfg, prep.dataset.t_pred, k, execution_of(cfg))
    c = dataclasses.replace(cfg, eval_k=(k,))
    out = []
    for s in scales:
        if sampler == "q":
            fn, name = scaled_q(model, params["cvae"], q, params[f"q_k{k}"], s), f"q_x{s:g}"
        else:
            fn, name = scaled_prior(model, params["cvae"], k, s), f"prior_x{s:g}"
        one = dataclasses.replace(method, predictors=lambda cfg_, ds, p, k_, fn=fn, name=name: {name: fn})
        with tempfile.TemporaryDirectory() as tmp:
            rec = eval_loop.evaluate(c, one, prep, params, Path(tmp), prep.dataset.name)[0]
        out.append({"scale": s, "K": k, "n_windows": rec["n_windows"], "metrics": {m: rec["metrics"][m] for m in METRICS}})
    return out


def plot(records: list[dict], path: Path, title: str, reference: dict | None) -> None:
    """Draws APD against ADE and FDE over the scales, with the paper's row as a point where given."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    apd = [r["metrics"]["APD"] for r in records]
    for m, style in (("ADE", "o-"), ("FDE", "s-")):
        ax.plot(apd, [r["metrics"][m] for r in records], style, label=f"{m}, this library")
        if reference:
            ax.plot([reference["APD"]], [reference[m]], "k" + style[0], mfc="none", ms=9, label=f"{m}, the paper's")
    for r in records:
        ax.annotate(f"s={r['scale']:g}", (r["metrics"]["APD"], r["metrics"]["ADE"]), textcoords="offset points", xytext=(3, -12), fontsize=7)
    ax.set_xlabel("APD (m)")
    ax.set_ylabel("error (m), best of K")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--workdir", required=True, help="the trained run's directory (its cvae checkpoints)")
    ap.add_argument("--seed", type=int, default=None, help="the run's seed (default: the config's)")
    ap.add_argument("--scales", default="0.25,0.5,0.75,1", help="comma-separated latent scales s")
    ap.add_argument("--sampler", choices=("prior", "q"), default="prior",
                    help="prior: the CVAE's N(0, s^2 I) draws; q: MOJO's Q latents on the low bands spread by s about their mean")
    ap.add_argument("--reference", default=None, help="the paper's row, APD,ADE,FDE (drawn on the plot)")
    ap.add_argument("--out", required=True, help="JSON of the records")
    ap.add_argument("--plot", default=None, help="PNG of APD against ADE / FDE")
    args = ap.parse_args(argv)
    cfg = load_config(args.config)
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    cfg = experiment.resolve(cfg)
    ds = experiment.load_data(cfg, args.data)
    prep = experiment.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    params = experiment.restore(cfg, prep, args.workdir)
    scales = [float(s) for s in args.scales.split(",")]
    records = sweep(cfg, prep, params, scales, args.sampler)
    for r in records:
        print(f"s={r['scale']:<5g} " + " ".join(f"{m}={r['metrics'][m]:.4f}" for m in METRICS), flush=True)
    about = {"command": "python experiments/latent_scale.py " + " ".join(argv if argv is not None else __import__("sys").argv[1:]),
             "config": Path(args.config).name, "seed": cfg.seed, "sampler": args.sampler, "records": records}
    Path(args.out).write_text(json.dumps(about, indent=1))
    if args.plot:
        ref = dict(zip(("APD", "ADE", "FDE"), map(float, args.reference.split(",")))) if args.reference else None
        what = "latents from N(0, s^2 I)" if args.sampler == "prior" else "Q latents spread by s about their mean"
        plot(records, Path(args.plot), f"{cfg.name}, seed {cfg.seed}: {what}, K = {records[0]['K']}", ref)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
