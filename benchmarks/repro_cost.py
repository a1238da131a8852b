"""What reproducing a paper's table costs: seconds per training step of every stage of a config, and hours to its budget.

    ~/jaxmotion-runs/quiet python benchmarks/repro_cost.py --data ~/data/data_3d_humaneva15.npz \\
        --configs experiments/configs/dlow_humaneva.py,experiments/configs/gsps_humaneva.py \\
        [--base REV] --out benchmarks/results/repro_cost_cpu.json

For each config file (read by path, so a row is added by naming another file) and each of its
stages that trains, the stage's own jitted train step as `jaxmotion run` builds it
(`train.runner`: the method's loss, optimiser and frozen inputs) is timed on one batch of the
stage's own batch source, already on the device (median of `--repeats` calls after three warm-up calls,
the state donated and stepped on as in training; a step shorter than `MIN_TIMED_S / --repeats` is
called more often, until about `MIN_TIMED_S` seconds are timed, so a millisecond step's median is
not that of three calls). Its matrix-product FLOPs are counted from the
jaxpr (`flops.matmul_flops`, every scan at its length), and the machine's peak is measured in the
same run (`peak.py`, the best n x n float32 product), so each stage has:

- `step_s`: seconds per training step;
- `pct_peak`: matrix-product FLOPs / step_s / peak (what the stage's products could run at);
- `hours`: `num_steps * step_s / 3600`, the stage's release budget on this machine.

The frozen inputs of a stage are the earlier stages' initial parameters (untrained: the timing is
the same). With `--base REV` every config also runs on the source tree of git revision REV
(`git archive`, imported in its own process), so old and new are side by side from one run on one
machine; the same config files are used for both. Each config runs in its own process; with `--rounds N` the
trees alternate N times and each stage keeps its fastest round (on a shared CPU, other jobs slow
stretches of a run down, and the fastest round is the least disturbed one).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine  # noqa: E402

GPU_NOTE = "not measured (no device lent)"
MIN_TIMED_S = 1.0  # a stage's timed calls together take at least about this long (at most 500 calls)


def stage_steps(config: str, data: str | None, stages: set[str] | None = None):
    """Yields `(cfg, stage, run, flops, batch size)` for each training stage of a config file: `run()` one donated train step.

    `run` steps the stage's own train step (`train.runner`) on one batch of its batch source, already on
    the device; `flops()` counts its matrix-product FLOPs from the jaxpr (every scan at its length).
    """
    import dataclasses

    import jax
    import numpy as np
    from jax.sharding import NamedSharding, PartitionSpec

    from benchmarks.flops import matmul_flops
    from jaxmotion import experiment
    from jaxmotion.config import load_config
    from jaxmotion.methods import get_method
    from jaxmotion.train import distributed, runner
    from jaxmotion.train.distributed import data_mesh

    cfg = experiment.resolve(load_config(config))
    cfg = dataclasses.replace(cfg, dataset=data or cfg.dataset)
    prep = experiment.prepare(experiment.load_data(cfg), max_test_windows=8, train_sampler=cfg.train_sampler)
    mesh = data_mesh()
    trained = {}
    for stage in get_method(cfg.method).stages(cfg, prep):
        state = runner.init_state(stage, trained)
        trained[stage.name] = state.params
        if stage.num_steps == 0 or (stages and stage.name not in stages):
            continue
        train_step = runner._train_step(stage)
        batch = distributed.global_batch(stage.batches(np.random.default_rng([stage.data_seed, 0])),
                                         NamedSharding(mesh, PartitionSpec("data")))
        key = jax.random.key(0)
        box = [distributed.replicate(state, NamedSharding(mesh, PartitionSpec()))]
        step_fn = jax.jit(train_step, donate_argnums=0)

        def run(box=box, step_fn=step_fn, batch=batch, key=key):
            box[0] = jax.block_until_ready(step_fn(box[0], batch, key)[0])

        def flops(train_step=train_step, state=state, batch=batch, key=key):
            # Dead code dropped first (the frozen networks' weight gradients a backward rule computes and XLA drops).
            from jax._src.interpreters.partial_eval import dce_jaxpr

            jaxpr = jax.make_jaxpr(train_step)(state, batch, key).jaxpr
            return matmul_flops(dce_jaxpr(jaxpr, [True] * len(jaxpr.outvars), instantiate=True)[0])

        yield cfg, stage, run, flops, int(jax.tree.leaves(batch)[0].shape[0])


def measure_config(config: str, data: str | None, repeats: int, stages: set[str] | None) -> dict:
    """Returns `{"config", "data", "stages": [...]}`: each training stage's step time, FLOPs and budget (module docstring)."""
    from benchmarks.harness import measure

    rows, cfg = [], None
    for cfg, stage, run, flops, batch in stage_steps(config, data, stages):
        gflop = flops() / 1e9
        t0 = time.perf_counter()
        run()
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        run()
        once = time.perf_counter() - t0
        calls = max(repeats, min(500, int(MIN_TIMED_S / max(once, 1e-6))))
        t = measure(run, warmup=1, repeats=calls)
        rows.append({"stage": stage.name, "num_steps": stage.num_steps, "step_s": t["median_s"], "min_s": t["min_s"], "calls": calls,
                     "compile_s": round(compile_s, 1), "matmul_gflop": gflop, "batch": batch})
        print(f"  {cfg.name}/{stage.name}: {t['median_s'] * 1e3:.1f} ms/step, {gflop:.2f} GFLOP", flush=True)
    return {"config": cfg.name if cfg else None, "config_file": config, "data": data, "stages": rows}


def source_tree(rev: str, into: Path) -> Path:
    """Returns a folder holding the files of git revision `rev` of this repository (`git archive`)."""
    into.mkdir(parents=True, exist_ok=True)
    tar = into / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(tar), rev], check=True)
    with tarfile.open(tar) as t:
        t.extractall(into / "src", filter="data")
    return into / "src"


def run_worker(src: Path, config: str, data: str | None, repeats: int, stages: str, out: Path, host_devices: int = 1) -> dict:
    """Returns `measure_config`'s record from a fresh process that imports `jaxmotion` from `src`, on `host_devices`
    CPU host devices (`jaxmotion run --host-devices`: the step data-parallel over them)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--src", str(src), "--configs", config,
           "--repeats", str(repeats), "--out", str(out)] + (["--data", data] if data else []) + (["--stages", stages] if stages else [])
    # The memory pages the `jaxmotion` command trains with (train/hugepages.py), in both trees.
    env = dict(os.environ, PYTHONPATH=str(src), GLIBC_TUNABLES="glibc.malloc.hugetlb=1")
    if host_devices > 1:
        from jaxmotion.train.host_devices import host_device_env

        env = host_device_env(env, host_devices)
    r = subprocess.run(cmd, env=env, cwd=str(src))
    if r.returncode != 0:
        return {"config_file": config, "error": f"worker exited with {r.returncode}"}
    return json.loads(out.read_text())


def fastest(records: list[dict]) -> dict:
    """Returns the first record with each stage's fastest round (`step_s` the least median), and every round's medians."""
    ok = [r for r in records if "stages" in r]
    if not ok:
        return records[0]
    out = dict(ok[0], stages=[])
    for i, s in enumerate(ok[0]["stages"]):
        rounds = [r["stages"][i] for r in ok]
        out["stages"].append(dict(min(rounds, key=lambda x: x["step_s"]), rounds_s=[x["step_s"] for x in rounds]))
    return out


def peak_gflops() -> float:
    """Returns this machine's float32 peak in GFLOP/s (`peak.py`, its own process)."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "peak.json"
        subprocess.run([sys.executable, "-m", "benchmarks.peak", "--framework", "jax", "--out", str(out),
                        "--sizes", "1024,2048"], check=True, cwd=str(ROOT))
        return json.loads(out.read_text())["peak_gflops"]["float32"]


def all_devices(rec: dict, n: int) -> dict:
    """Returns a worker's record with every stage's FLOPs those of all its `n` devices (the jaxpr of a step written per
    device, `jax.shard_map`, counts one device's share of the batch)."""
    for s in rec.get("stages", []):
        s["matmul_gflop"] *= n
    return rec


def annotate(rec: dict, peak: float) -> dict:
    """Adds `pct_peak`, `hours` and the GPU note to every stage of a worker's record."""
    for s in rec.get("stages", []):
        s["pct_peak"] = 100 * s["matmul_gflop"] / s["step_s"] / peak
        s["hours"] = s["num_steps"] * s["step_s"] / 3600
        s["gpu"] = GPU_NOTE
    return rec


def table(doc: dict) -> str:
    """Returns the markdown table of a results document: one row per stage, the base's figures beside where measured."""
    base = {(r.get("config_file"), s["stage"]): s for r in doc.get("base", []) for s in r.get("stages", [])}
    head = "| config | stage | steps | batch | s / step | % of peak | hours on this CPU | GPU |"
    sep = "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- |"
    if base:
        head = "| config | stage | steps | batch | s / step (base) | s / step | speed-up | % of peak | hours (base) | hours | GPU |"
        sep = "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
    lines = [head, sep]
    for r in doc["new"]:
        for s in r.get("stages", []):
            name = Path(r["config_file"]).name
            if base:
                b = base.get((r["config_file"], s["stage"]))
                old = f"{b['step_s']:.3f}" if b else "-"
                up = f"{b['step_s'] / s['step_s']:.2f}x" if b else "-"
                oh = f"{b['hours']:.1f}" if b else "-"
                lines.append(f"| {name} | {s['stage']} | {s['num_steps']} | {s['batch']} | {old} | {s['step_s']:.3f} | {up} | "
                             f"{s['pct_peak']:.0f}% | {oh} | {s['hours']:.1f} | {s['gpu']} |")
            else:
                lines.append(f"| {name} | {s['stage']} | {s['num_steps']} | {s['batch']} | {s['step_s']:.3f} | "
                             f"{s['pct_peak']:.0f}% | {s['hours']:.1f} | {s['gpu']} |")
        if "error" in r:
            lines.append(f"| {Path(r['config_file']).name} | ({r['error']}) | | | | | | |")
    return "\n".join(lines)


def host_table(doc: dict) -> str:
    """Returns the markdown table of one device against `doc["host_devices"]` host devices, stage by stage (same run)."""
    n = doc["host_devices"]
    host = {(r.get("config_file"), s["stage"]): s for r in doc.get("host", []) for s in r.get("stages", [])}
    lines = [f"| config | stage | steps | batch | s / step, 1 device | s / step, {n} host devices | speed-up | hours, 1 device | "
             f"hours, {n} host devices |", "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in doc["new"]:
        for s in r.get("stages", []):
            h = host.get((r["config_file"], s["stage"]))
            if h is None:
                continue
            lines.append(f"| {Path(r['config_file']).name} | {s['stage']} | {s['num_steps']} | {s['batch']} | {s['step_s']:.3f} | "
                         f"{h['step_s']:.3f} | {s['step_s'] / h['step_s']:.2f}x | {s['hours']:.1f} | {h['hours']:.1f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--configs", required=True, help="config files, comma-separated")
    ap.add_argument("--data", default=None, help="dataset path (default: each config's)")
    ap.add_argument("--stages", default="", help="only these stage names, comma-separated (default: all that train)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=1, help="measure every config this many times, trees alternating")
    ap.add_argument("--base", default=None, help="also measure git revision BASE's source, side by side")
    ap.add_argument("--rev", default=None, help="measure git revision REV's source instead of this checkout's")
    ap.add_argument("--base-label", default=None, help="how the table names the base (default: BASE)")
    ap.add_argument("--host-devices", type=int, default=1, metavar="N",
                    help="also measure every config on N CPU host devices (jaxmotion run --host-devices N), alternating")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--src", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.host_devices < 1:
        ap.error(f"--host-devices: expected a count >= 1, got {args.host_devices}")
    configs = [str(Path(c).resolve()) for c in args.configs.split(",") if c]
    data = str(Path(args.data).expanduser()) if args.data else None
    if args.worker:
        sys.path.insert(0, args.src)
        rec = measure_config(configs[0], data, args.repeats, set(filter(None, args.stages.split(","))))
        args.out.write_text(json.dumps(rec))
        return 0
    m = machine()
    print(f"CPU: {m['cpu']} ({m['logical_cpus']} logical CPUs)", flush=True)
    peak = peak_gflops()
    print(f"peak float32: {peak:.1f} GFLOP/s", flush=True)
    argv = sys.argv[1:] if argv is None else argv
    # The command as the docs print it: the base revision written as BASE (docs name no commits), home as ~.
    shown = ["BASE" if args.base and a == args.base else a.replace(str(Path.home()), "~") for a in argv]
    shown = [shlex.quote(a) if " " in a else a for a in shown]  # a label with spaces, quoted as it was typed
    doc = {"machine": m, "peak_gflops": peak, "base_rev": args.base, "rev": args.rev, "base_label": args.base_label or "BASE",
           "new": [], "base": [], "host": [], "host_devices": args.host_devices,
           "command": "python benchmarks/repro_cost.py " + " ".join(shown)}
    with tempfile.TemporaryDirectory() as d:
        base_src = source_tree(args.base, Path(d)) if args.base else None
        # --rev: the source of that revision alone in the "new" columns (a config that needs it).
        new_src = source_tree(args.rev, Path(d) / "rev") if args.rev else ROOT
        # (name, source, host devices): this checkout (or --rev) on one device, the base's, this one on N host devices.
        trees = ([("new", new_src, 1)] + ([("base", base_src, 1)] if base_src is not None else [])
                 + ([("host", new_src, args.host_devices)] if args.host_devices > 1 else []))
        runs = {(name, c): [] for name, _, _ in trees for c in configs}
        # Rounds alternate the trees config by config, so a stretch of a slower machine (other jobs on a
        # shared CPU) falls on both; each stage keeps its fastest round.
        for r in range(args.rounds):
            for i, c in enumerate(configs):
                for name, src, n in trees:
                    runs[name, c].append(run_worker(src, c, data, args.repeats, args.stages, Path(d) / f"{name}{i}_{r}.json", n))
        # The peak again after the stages; the faster of the two (the less disturbed) is the machine's.
        peaks = [peak, peak_gflops()]
        doc["peak_gflops"] = peak = max(peaks)
        doc["peaks_gflops"] = peaks
        for name, _, n in trees:
            doc[name] = [annotate(all_devices(fastest(runs[name, c]), n), peak) for c in configs]
    print(table(doc))
    if doc["host"]:
        print(host_table(doc))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(doc, indent=1))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
