"""How much of a real training step is host work: the bound on "several optimiser steps per jitted call".

    flock /tmp/jaxmotion-heavy.lock python benchmarks/loop_overhead.py                  # ~5 min on the 2-core CPU
    python benchmarks/loop_overhead.py --config experiments/configs/divsamp_bandai.py --data ../shared/data/bandai-namco-2

Issue 18 lists "several optimiser steps per jitted call (`lax.scan` over steps with batches sampled on
device)" as a lever: it removes the per-step host work of `jaxmotion.train.loop.fit` (drawing the batch
with numpy, placing it on the device, dispatching the step, the checkpoint manager's per-step check,
the log and progress bar). This script measures that work on the stages `jaxmotion run` trains, built
by the method's own `stages` from the config (the real batch source on the real training windows), in
one process, per stage:

- `step`: the jitted train step alone (donating its state, as `fit` does), on one batch already on
  the device (median of `--steps` calls, each waited for);
- `host`: drawing and placing one batch (`stage.batches(rng)`, `distributed.global_batch`), alone;
- `fit`: a step inside `loop.fit` (checkpoint interval as the config), after a warm-up `fit` that
  compiles: the time between its first and last log line (every 10 steps, each taken after the step's
  metrics are fetched) over the steps between them.

The most a multi-step call could save is `fit - step` per step (all of the loop's host work, and the
overlap jax's asynchronous dispatch already gives is counted as a saving too, so it is an upper bound).
Prints the CPU and the figures; `--json OUT` writes them. Without `--data` (and with the config's
dataset absent) it runs on the synthetic data.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine, measure  # noqa: E402


def measure_stage(stage, trained: dict, steps: int, ckpt_every: int) -> dict:
    """Returns `{"step_ms", "host_ms", "fit_ms", "bound"}` for one stage (see the module docstring)."""
    import jax
    import numpy as np

    from jaxmotion.train import distributed
    from jaxmotion.train.distributed import data_mesh
    from jaxmotion.train import loop, runner
    from jax.sharding import NamedSharding, PartitionSpec

    mesh = data_mesh()
    sharding = NamedSharding(mesh, PartitionSpec("data"))
    train_step = runner._train_step(stage)
    batches = stage.batches or (lambda rng: None)

    def place(i):
        return distributed.global_batch(batches(np.random.default_rng([stage.data_seed, i])), sharding)

    host_ms = measure(lambda: jax.block_until_ready(place(0)), warmup=0, repeats=steps)["median_s"] * 1e3

    box = [distributed.replicate(runner.init_state(stage, trained), NamedSharding(mesh, PartitionSpec()))]
    step_fn = jax.jit(train_step, donate_argnums=0)  # as fit runs it
    batch, key = place(0), jax.random.key(0)

    def run_step():  # the donated state is stepped on, as in a training loop
        box[0] = jax.block_until_ready(step_fn(box[0], batch, key)[0])

    step_ms = measure(run_step, warmup=1, repeats=steps)["median_s"] * 1e3

    with tempfile.TemporaryDirectory() as d:
        kw = dict(seed=stage.data_seed, ckpt_every=ckpt_every, log_every=10, desc=stage.name)
        loop.fit(runner.init_state(stage, trained), train_step, batches, num_steps=3, workdir=Path(d) / "warm", **kw)
        n = 10 * max(steps // 10 + 1, 2)  # at least two log lines to time between
        out = loop.fit(runner.init_state(stage, trained), train_step, batches, num_steps=n, workdir=Path(d) / "fit", **kw)
        # The log's `time_s` is taken after fetching the step's metrics (which waits for it): the time
        # between the first and the last log line is `n - 10` steps of the loop, compilation and the
        # final checkpoint excluded.
        lines = [json.loads(line) for line in (Path(d) / "fit" / "log.jsonl").read_text().splitlines()]
        first, last = lines[0], lines[-1]
        fit_ms = (last["time_s"] - first["time_s"]) * 1e3 / (last["step"] - first["step"])
    return {
        "stage": stage.name, "step_ms": round(step_ms, 2), "host_ms": round(host_ms, 3), "fit_ms": round(fit_ms, 2),
        "bound": round(max(fit_ms - step_ms, 0.0) / fit_ms, 4), "params": out.params,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "experiments" / "configs" / "dlow_bandai.py"))
    ap.add_argument("--data", default=None, help="dataset path (default: the config's; synthetic where that is absent)")
    ap.add_argument("--steps", type=int, default=60, help="timed steps per measurement")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.steps < 5:
        ap.error("--steps must be at least 5")

    import dataclasses

    from jaxmotion import experiment
    from jaxmotion.config import load_config
    from jaxmotion.methods import get_method

    cfg = experiment.resolve(load_config(args.config))
    data = args.data or cfg.dataset
    if data != "synthetic" and not Path(data).expanduser().exists():
        print(f"{data} is absent: measuring on the synthetic data instead")
        data = "synthetic"
    cfg = dataclasses.replace(cfg, dataset=data)
    m = machine()
    print(f"CPU: {m['cpu']} ({m['logical_cpus']} logical CPUs); config {cfg.name}, data {data}, {args.steps} steps per figure")
    prep = experiment.prepare(experiment.load_data(cfg), max_test_windows=8, train_sampler=cfg.train_sampler)
    method = get_method(cfg.method)
    trained, rows = {}, []
    for stage in method.stages(cfg, prep):
        if stage.num_steps == 0:
            continue
        r = measure_stage(stage, trained, args.steps, cfg.ckpt_every)
        trained[stage.name] = r.pop("params")  # the next stage's frozen inputs (briefly trained, enough for timing)
        rows.append(r)
        print(
            f"{r['stage']:>10}: step alone {r['step_ms']:8.2f} ms | host work (draw + place a batch) {r['host_ms']:7.3f} ms | "
            f"inside loop.fit {r['fit_ms']:8.2f} ms per step | most a multi-step call could save: {100 * r['bound']:.1f}%"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"machine": m, "config": cfg.name, "data": data, "steps": args.steps, "stages": rows}, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
