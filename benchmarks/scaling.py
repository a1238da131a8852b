"""Data-parallel scaling: training steps/s and evaluation windows/s over devices and processes.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/scaling.py --method dlow --out benchmarks/results/scaling_dlow_run1
    python benchmarks/scaling.py --summary benchmarks/results/scaling_dlow_run*.json   # the median table of several runs
    python benchmarks/scaling.py --tiny                                   # smoke test (tiny sizes, about a minute)
    python benchmarks/scaling.py --platform gpu                           # 1, 2, 4... GPUs and 1, 2 processes (benchmarks/gpu.sh)

Each setting runs in its own process(es), started here: one process with 1, 2 and 4 devices (on CPU,
host devices forced with `--xla_force_host_platform_device_count`; on GPU, the first n GPUs), and 1
and 2 processes on localhost joined by `jax.distributed` (one device each). Every setting trains the
same CVAE stage (`--method dlow`: DLow's GRU CVAE; `divsamp`: DivSamp's GCN CVAE with BatchNorm, no
recurrence) through `jaxmotion.train.loop.fit` with the same global batch (so a step is the same work:
strong scaling), then predicts K futures for the same test windows with `experiment.predict_chunks`
(each device predicting its share). The times exclude compilation: steps/s
is measured from the log lines after the warm-up steps, windows/s on the second pass over the windows.

On a CPU, forced host devices and extra processes share the same cores, so this measures the overhead
of sharding, collectives and process coordination, not a speedup; a speedup needs devices with their
own compute (GPUs, TPU chips, or hosts).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 1800
PREDICTOR = {"dlow": "cvae", "divsamp": "divsamp_cvae"}  # the CVAE's own sampler, N(0, I) latents
STAGE = {"dlow": "DLow CVAE (GRUs)", "divsamp": "DivSamp CVAE (GCNs, BatchNorm)"}


def _settings(args) -> list[dict]:
    """Returns the settings to measure: `{name, devices, processes}`."""
    out = [{"name": f"{d} device{'s' * (d > 1)}", "devices": d, "processes": 1, "distributed": False} for d in args.devices]
    out += [{"name": f"{p} process{'es' * (p > 1)}", "devices": 1, "processes": p, "distributed": True} for p in args.processes]
    return out


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(platform_: str, devices: int, process: int, processes: int) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu" if platform_ == "cpu" else "cuda")
    if platform_ == "cpu":
        from jaxmotion.train.host_devices import host_device_env

        env = host_device_env(env, devices)
    elif processes > 1:  # one GPU per process
        env["CUDA_VISIBLE_DEVICES"] = str(process)
    else:
        env["CUDA_VISIBLE_DEVICES"] = ",".join(map(str, range(devices)))
    return env


def run_setting(s: dict, args) -> dict:
    """Runs one setting in its process(es) and returns process 0's measurement."""
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        procs = []
        for i in range(s["processes"]):
            cmd = [sys.executable, __file__, "--worker", "--workdir", str(Path(tmp) / "work"), "--steps", str(args.steps),
                   "--warmup", str(args.warmup), "--batch", str(args.batch), "--windows", str(args.windows), "--k", str(args.k),
                   "--eval-batch", str(args.eval_batch), "--method", args.method, "--batch-norm", args.batch_norm] + (["--tiny"] if args.tiny else [])
            if s["distributed"]:
                cmd += ["--coordinator-address", f"127.0.0.1:{port}", "--num-processes", str(s["processes"]), "--process-id", str(i)]
            procs.append(subprocess.Popen(cmd, env=_env(args.platform, s["devices"], i, s["processes"]), stdout=subprocess.PIPE,
                                          stderr=subprocess.PIPE, text=True))
        outs = []
        for p in procs:
            try:
                outs.append(p.communicate(timeout=TIMEOUT))
            finally:
                if p.poll() is None:
                    p.kill()
        for p, (_, err) in zip(procs, outs):
            if p.returncode != 0:
                raise SystemExit(f"setting {s['name']}: a worker failed (exit {p.returncode}):\n{err[-3000:]}")
    return json.loads(outs[0][0].strip().splitlines()[-1])


def worker(args) -> None:
    """Measures one setting in this process (one of `--num-processes` when given) and prints a JSON line (process 0)."""
    from jaxmotion.train import distributed

    distributed.initialize(args.coordinator_address, args.num_processes, args.process_id)
    import jax

    from jaxmotion import experiment
    from jaxmotion.config import Config
    from jaxmotion.models.divsamp import DivSampConfig
    from jaxmotion.models.dlow import CVAEConfig, DLowConfig
    from jaxmotion.train.loop import fit, make_bn_train_step, make_train_step
    from jaxmotion.train.runner import init_state

    num_steps = args.warmup + args.steps
    if args.method == "dlow":
        sizes = dict(nz=8, nh_rnn=16, nh_mlp=(16,)) if args.tiny else {}
        method_config = DLowConfig(cvae=CVAEConfig(num_steps=num_steps, batch_size=args.batch, **sizes))
    else:
        sizes = dict(hidden=16, nz=8) if args.tiny else {}
        method_config = DivSampConfig(cvae_num_steps=num_steps, cvae_batch_size=args.batch, **sizes)
    cfg = experiment.resolve(Config(method=args.method, method_config=method_config, eval_k=(args.k,), max_test_windows=args.windows,
                                    eval_batch=args.eval_batch, batch_norm=args.batch_norm))
    prep = experiment.prepare(experiment.load_data(cfg), cfg.max_test_windows)
    method = experiment.get_method(cfg.method)
    stage = method.stages(cfg, prep)[0]  # the CVAE
    workdir = Path(args.workdir)
    # Log lines every --warmup steps (the first ends the warm-up); the one checkpoint is written after the last line.
    make = make_bn_train_step if stage.batch_norm else make_train_step
    state = fit(init_state(stage), make(stage.loss, stage.optimizer), stage.batches, num_steps=num_steps,
                workdir=workdir, seed=0, ckpt_every=10**9, log_every=args.warmup, desc="scaling")
    steps_per_s = None
    if distributed.is_main():
        lines = [json.loads(line) for line in (workdir / "log.jsonl").read_text().splitlines()]
        t = {r["step"]: r["time_s"] for r in lines}
        steps_per_s = args.steps / (t[num_steps] - t[args.warmup])
    fn = experiment.predictors(cfg, prep.dataset, {"cvae": state.params}, args.k)[PREDICTOR[args.method]]
    key = jax.random.key(0)
    for _ in experiment.predict_chunks(fn, prep.x, key, cfg.eval_batch):  # compiles
        pass
    t0 = time.perf_counter()
    n = sum(p.shape[0] for p in experiment.predict_chunks(fn, prep.x, key, cfg.eval_batch))
    windows_per_s = n / (time.perf_counter() - t0)
    if distributed.is_main():
        dev = jax.devices()[0]
        print(json.dumps({"steps_per_s": steps_per_s, "windows_per_s": windows_per_s, "n_windows": n, "devices": jax.device_count(),
                          "processes": jax.process_count(), "device": f"{dev.platform}:{dev.device_kind}"}), flush=True)


def _table(rows: list[dict], args, cores: int) -> str:
    base = rows[0]
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from harness import machine

    lines = [
        f"Run {time.strftime('%Y-%m-%dT%H:%M:%S')} on **{machine()['cpu']}**, {cores} logical CPUs "
        f"({platform.platform()}); jax {_jax_version()}; device: {base['device']}.",
        "",
        f"Command: `python benchmarks/scaling.py {' '.join(sys.argv[1:])}`. {STAGE[args.method]} ({'tiny' if args.tiny else 'default'} sizes), "
        f"global batch {args.batch}: {args.steps} training steps after {args.warmup} warm-up steps; K = {args.k} futures for "
        f"{base['n_windows']} test windows in batches of {args.eval_batch}. Relative: to the first row.",
        "",
        "| setting | devices | processes | steps/s | relative | windows/s | relative |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(f"| {r['name']} | {r['devices']} | {r['processes']} | {r['steps_per_s']:.2f} | "
                     f"{r['steps_per_s'] / base['steps_per_s']:.2f} | {r['windows_per_s']:.1f} | {r['windows_per_s'] / base['windows_per_s']:.2f} |")
    frac = _process_fraction(rows)
    if frac is not None:
        lines += ["", f"2 processes reach {frac['steps']:.2f}x the 1-process training steps/s and {frac['windows']:.2f}x its "
                      "evaluation windows/s."]
    if args.platform == "cpu":
        lines += ["", f"On CPU every setting shares the same {cores} cores: the forced host devices and the extra process split "
                      "them, so the table measures the overhead of sharding, collectives and process coordination, not a speedup."]
    return "\n".join(lines)


def _process_fraction(rows: list[dict]) -> dict | None:
    """Returns `{"steps", "windows"}`: the 2-process rates over the 1-process ones (None without both settings)."""
    by = {r["name"]: r for r in rows}
    one, two = by.get("1 process"), by.get("2 processes")
    if one is None or two is None:
        return None
    return {"steps": two["steps_per_s"] / one["steps_per_s"], "windows": two["windows_per_s"] / one["windows_per_s"]}


def summary(paths: list[str]) -> str:
    """Returns the Markdown table of the medians over several runs' JSON files (`--out`) of one method."""
    runs = [json.loads(Path(p).read_text()) for p in paths]
    methods = {r["args"].get("method", "dlow") for r in runs}
    if len(methods) != 1:
        raise SystemExit(f"--summary: the files are runs of several methods {sorted(methods)}; give one method's runs")
    med = lambda xs: float(statistics.median(xs))  # noqa: E731
    names = [r["name"] for r in runs[0]["rows"]]
    rows = {n: [next(r for r in run["rows"] if r["name"] == n) for run in runs] for n in names}
    base = med([r["steps_per_s"] for r in rows[names[0]]])
    fracs = [f for f in (_process_fraction(run["rows"]) for run in runs) if f is not None]
    lines = [f"{STAGE[methods.pop()]}, median of {len(runs)} runs ({', '.join(Path(p).name for p in paths)}):", "",
             "| setting | steps/s (median) | runs | relative | windows/s (median) |", "|---|---:|---|---:|---:|"]
    for n in names:
        sp = [r["steps_per_s"] for r in rows[n]]
        lines.append(f"| {n} | {med(sp):.2f} | {' / '.join(f'{v:.2f}' for v in sp)} | {med(sp) / base:.2f} | "
                     f"{med([r['windows_per_s'] for r in rows[n]]):.1f} |")
    if fracs:
        each = " / ".join(f"{f['steps']:.2f}" for f in fracs)
        lines += ["", f"2 processes / 1 process, training steps/s: {each} "
                      f"(median {med([f['steps'] for f in fracs]):.2f}x); evaluation windows/s: median "
                      f"{med([f['windows'] for f in fracs]):.2f}x (each ratio within one run)."]
    return "\n".join(lines)


def _jax_version() -> str:
    from importlib.metadata import version

    return version("jax")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--platform", choices=("cpu", "gpu"), default="cpu")
    p.add_argument("--method", choices=sorted(PREDICTOR), default="dlow", help="whose CVAE stage to train")
    p.add_argument("--summary", nargs="+", metavar="JSON", help="print the median table of these runs' --out JSON files, run nothing")
    p.add_argument("--devices", type=int, nargs="+", default=[1, 2, 4], help="device counts of the one-process settings")
    p.add_argument("--processes", type=int, nargs="+", default=[1, 2], help="process counts of the localhost settings (one device each)")
    p.add_argument("--steps", type=int, default=40, help="timed training steps (a multiple of --warmup)")
    p.add_argument("--warmup", type=int, default=10, help="training steps before the timing starts (compilation included)")
    p.add_argument("--batch", type=int, default=64, help="global batch (DLow's); a multiple of every device count")
    p.add_argument("--windows", type=int, default=256, help="test windows to predict (evenly spaced, at most all 280)")
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--eval-batch", type=int, default=64)
    p.add_argument("--batch-norm", choices=("global", "per_device"), default="global",
                   help="Config.batch_norm: BatchNorm moments of the global batch (exact) or of each device's rows")
    p.add_argument("--tiny", action="store_true", help="smoke test: tiny network, few steps and windows")
    p.add_argument("--out", default=None, help="also write the rows as JSON and the table as Markdown here (a path without suffix)")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--workdir", help=argparse.SUPPRESS)
    p.add_argument("--coordinator-address", help=argparse.SUPPRESS)
    p.add_argument("--num-processes", type=int, help=argparse.SUPPRESS)
    p.add_argument("--process-id", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker(args)
        return 0
    if args.summary:
        print(summary(args.summary))
        return 0
    if args.tiny:
        args.steps, args.warmup, args.windows = min(args.steps, 8), min(args.warmup, 4), min(args.windows, 32)
    bad = [d for d in args.devices + args.processes if args.batch % d or args.eval_batch % d]
    if bad or args.steps % args.warmup:
        raise SystemExit(f"--batch {args.batch} and --eval-batch {args.eval_batch} must be multiples of every device and process "
                         f"count (not of {bad}); --steps {args.steps} a multiple of --warmup {args.warmup}")
    rows = []
    for s in _settings(args):
        t0 = time.perf_counter()
        r = dict(s, **run_setting(s, args))
        rows.append(r)
        print(f"{s['name']}: {r['steps_per_s']:.2f} steps/s, {r['windows_per_s']:.1f} windows/s ({time.perf_counter() - t0:.0f} s)",
              file=sys.stderr, flush=True)
    table = _table(rows, args, os.cpu_count() or 1)
    print(table)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".json").write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
        out.with_suffix(".md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
