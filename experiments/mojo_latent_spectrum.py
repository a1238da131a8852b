"""Plots MOJO's latent spectrum: mean |mu| and mean |log sigma^2| per DCT band over a data set (MOJO Fig. S5).

    python experiments/mojo_latent_spectrum.py --config experiments/configs/mojo_bandai.py \
        --data ../shared/data/bandai-namco-2 --workdir /tmp/runs/mojo_bandai \
        --out experiments/results/mojo_latent_spectrum.png

Encodes every test window (X, Y) with the trained CVAE's posterior q(z | X, Y). Bands whose means
stay near 0 and whose log-variances stay near 0 carry no information (the posterior equals the
N(0, I) prior there); the paper finds the information in the low bands, which is why MOJO samples
only those with DLow. Writes the PNG and a JSON of the numbers beside it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from jaxmotion import experiment  # noqa: E402
from jaxmotion.config import load_config  # noqa: E402
from jaxmotion.models import mojo  # noqa: E402
from jaxmotion.methods import get_method  # noqa: E402
from jaxmotion.train import runner  # noqa: E402


def spectrum(cfg, prep, params, batch: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """Returns per-band `(mean |mu|, mean |logvar|)` over all test windows."""
    model = mojo.cvae_model(cfg.method_config, prep.dataset.dim, prep.dataset.t_pred)
    enc = jax.jit(lambda x, y: model.apply(params, x, y, method=mojo.MojoCVAE.encode))
    mus, lvs = [], []
    for s in range(0, len(prep.windows), batch):
        mu, lv = enc(jnp.asarray(prep.x[s : s + batch]), jnp.asarray(prep.y[s : s + batch]))
        mus.append(np.abs(np.asarray(mu)).mean(-1))
        lvs.append(np.abs(np.asarray(lv)).mean(-1))
    return np.concatenate(mus).mean(0), np.concatenate(lvs).mean(0)


def plot(mu: np.ndarray, lv: np.ndarray, n_low: int, out: Path, title: str) -> Path:
    bands = np.arange(len(mu))
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for ax, v, label in [(axes[0], mu, "mean |mu|"), (axes[1], lv, "mean |log sigma^2|")]:
        ax.bar(bands, v, color=["tab:red" if b < n_low else "tab:gray" for b in bands])
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[1].set_xlabel(f"DCT band (red: the lowest {n_low}, sampled by DLow in MOJO)")
    axes[0].set_title(title, fontsize=9)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True)
    p.add_argument("--data", default=None)
    p.add_argument("--workdir", required=True, help="the trained run (its cvae/ checkpoints)")
    p.add_argument("--out", default="experiments/results/mojo_latent_spectrum.png")
    args = p.parse_args(argv)
    cfg = load_config(args.config)
    if cfg.method != "mojo":
        raise SystemExit(f"--config {args.config}: method is {cfg.method!r}, expected 'mojo'")
    method = get_method("mojo")
    m = method.settings(cfg)
    if m.latent != "dct":
        raise SystemExit(f"--config {args.config}: latent {m.latent!r} has no DCT bands to plot")
    ds = experiment.load_data(cfg, args.data)
    prep = experiment.prepare(ds, cfg.max_test_windows)
    params = runner.restore_stage(method, method.stages(cfg, prep)[0], Path(args.workdir), {})
    mu, lv = spectrum(cfg, prep, params)
    n_low = mojo.num_low_bands(m, ds.t_pred)
    title = f"{m.variant} latent spectrum on {ds.name}: {len(prep.windows)} test windows, {len(mu)} bands x {m.nz}"
    out = plot(mu, lv, n_low, Path(args.out), title)
    low_share = float(mu[:n_low].sum() / mu.sum())
    record = {"config": cfg.name, "n_windows": len(prep.windows), "n_low": n_low, "mean_abs_mu": mu.tolist(),
              "mean_abs_logvar": lv.tolist(), "low_band_share_of_mean_abs_mu": low_share}
    out.with_suffix(".json").write_text(json.dumps(record, indent=1))
    print(f"wrote {out} and {out.with_suffix('.json').name}; lowest {n_low} bands hold {100 * low_share:.0f}% of sum mean|mu|")
    return 0


if __name__ == "__main__":
    sys.exit(main())
