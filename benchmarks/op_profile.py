"""Where the time goes: per-op profiles of benchmark cases, jaxmotion (XLA thunks) and PyTorch eager (ATen ops).

    python benchmarks/op_profile.py --cases dlow/sample/b64/k50/t60,dlow/train_cvae/b64/t60
    python benchmarks/op_profile.py --config experiments/configs/dlow_humaneva.py --data DATA --stages dlow_k50

With `--config`, the training steps of a config file's stages as `jaxmotion run` builds them
(`repro_cost.stage_steps`, jaxmotion only) instead of the benchmark's cases.

jaxmotion: `jax.profiler.trace` with `--xla_cpu_enable_xprof_traceme`, every XLA:CPU thunk's wall
time summed by name (matrix products run as `ynn_fusion` / `xnn_fusion` / `dot` thunks, often with
their bias and activation fused in). PyTorch: `torch.profiler`, self CPU time per ATen op. Diagnostic only:
profiling perturbs the timings it explains; `run.py` is the benchmark.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import sys
import tempfile
import time
from pathlib import Path

if "--xla_cpu_enable_xprof_traceme" not in os.environ.get("XLA_FLAGS", ""):  # once, also across the huge-page restart
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_enable_xprof_traceme=true").strip()
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import Case, Settings  # noqa: E402
from jaxmotion.train import hugepages  # noqa: E402

WRAPPERS = ("Pjit", "PjRt", "Execute", "Thunk", "Threadpool", "Parse", "Handle", "Allocate", "Wait", "$", "Python",
            "end:", "Await", "CreateOutputs", "Common", "while", "call", "conditional")


def parse_case(text: str) -> Case:
    model, kind, *rest = text.split("/")
    kw = {"batch": 1, "k": 0, "t_pred": 0, "steps": 0}
    for part in rest:
        key = {"b": "batch", "k": "k", "t": "t_pred", "s": "steps"}[part[0]]
        kw[key] = int(part[1:])
    return Case(model, kind, **kw)


def jax_profile(case: Case, s: Settings, runs: int) -> dict:
    from benchmarks import jax_bench

    run, _, _ = getattr(jax_bench.Builders(s), case.model)(case)
    return jax_profile_run(run, runs)


def jax_profile_run(run, runs: int) -> dict:
    """Returns `{"wall_s", "ops"}`: `run()`'s wall time and every XLA thunk's time per call, by name."""
    import jax

    for _ in range(2):
        run()
    t0 = time.perf_counter()
    for _ in range(runs):
        run()
    wall = (time.perf_counter() - t0) / runs
    with tempfile.TemporaryDirectory() as tmp:
        with jax.profiler.trace(tmp, create_perfetto_trace=True):
            for _ in range(runs):
                run()
        trace = json.load(gzip.open(glob.glob(f"{tmp}/**/*.trace.json.gz", recursive=True)[-1]))
    events = trace["traceEvents"] if isinstance(trace, dict) else trace
    by_name: dict[str, float] = collections.Counter()
    for e in events:
        name = e.get("name", "")
        if e.get("ph") == "X" and not name.startswith(WRAPPERS):
            by_name[name] += e.get("dur", 0.0) / 1e6 / runs
    return {"wall_s": wall, "ops": dict(by_name)}


def torch_profile(case: Case, s: Settings, runs: int) -> dict:
    import torch
    from torch.profiler import ProfilerActivity, profile

    from benchmarks.torch_ref import bench

    run = getattr(bench.Builders(s, False), case.model)(case)
    for _ in range(2):
        run()
    t0 = time.perf_counter()
    for _ in range(runs):
        run()
    wall = (time.perf_counter() - t0) / runs
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(runs):
            run()
    ops = {e.key: e.self_cpu_time_total / 1e6 / runs for e in prof.key_averages()}
    return {"wall_s": wall, "ops": ops, "threads": torch.get_num_threads()}


def category(fw: str, name: str) -> str:
    n = name.lower()
    if fw == "jax":
        if any(t in n for t in ("ynn", "xnn", "dot", "gemm", "onednn", "matmul")):
            return "matmul (+ fused bias/activation)"
        if "fusion" in n:
            return "elementwise fusions"
        if any(t in n for t in ("copy", "slice", "concatenate", "transpose", "broadcast", "pad", "dynamic")):
            return "copies / slicing"
        return "other"
    if any(t in n for t in ("addmm", "mm", "linear", "matmul", "bmm", "gru", "rnn", "baddbmm")):
        return "matmul (+ fused bias/activation)"
    if any(t in n for t in ("tanh", "sigmoid", "mul", "add", "sub", "exp", "rsub", "div", "pow", "abs", "sum", "mean",
                            "norm", "batch_norm", "clamp", "sqrt", "log", "min", "amin", "adam", "foreach")):
        return "elementwise fusions"
    if any(t in n for t in ("cat", "stack", "copy", "slice", "select", "view", "reshape", "expand", "repeat", "index",
                            "transpose", "permute", "chunk", "split", "unbind", "contiguous", "clone", "empty", "zero",
                            "fill", "as_strided", "t", "narrow", "unsafe")):
        return "copies / slicing / views"
    return "other"


def summary(fw: str, prof: dict) -> list[str]:
    total = sum(prof["ops"].values())
    cats: dict[str, float] = collections.Counter()
    for name, t in prof["ops"].items():
        cats[category(fw, name)] += t
    lines = [f"  {fw}: {prof['wall_s'] * 1e3:.2f} ms per call; profiled op time {total * 1e3:.2f} ms"]
    lines += [f"    {c:36s} {t * 1e3:9.2f} ms  {100 * t / max(total, 1e-12):5.1f}%" for c, t in cats.most_common()]
    top = sorted(prof["ops"].items(), key=lambda kv: -kv[1])[:8]
    lines.append("    top ops: " + ", ".join(f"{n} {t * 1e3:.2f} ms" for n, t in top))
    return lines


def main():
    # The memory pages run.py measures with (its default `--hugepages on`): without them XLA:CPU's
    # large buffers fault in 4 KiB at a time and the profile blames the ops that first touch them
    # (DLow's CVAE step: 71.9 ms per call and a 4.5 ms input product, against 52.6 and 1.3 with them).
    hugepages.exec_with_hugepages()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", default="dlow/sample/b64/k50/t60,dlow/train_cvae/b64/t60")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--framework", choices=("jax", "torch", "both"), default="both")
    ap.add_argument("--out", help="also write the raw per-op times as JSON here")
    ap.add_argument("--config", help="profile this config file's training stages instead of --cases")
    ap.add_argument("--data", default=None, help="with --config: the dataset path (default: the config's)")
    ap.add_argument("--stages", default="", help="with --config: only these stages, comma-separated")
    args = ap.parse_args()
    if args.config:
        from benchmarks.repro_cost import stage_steps

        raw = {}
        for cfg, stage, run, _, _ in stage_steps(args.config, args.data, set(filter(None, args.stages.split(",")))):
            print(f"{cfg.name}/{stage.name}")
            raw[f"{cfg.name}/{stage.name}"] = {"jax": (p := jax_profile_run(run, args.runs))}
            print("\n".join(summary("jax", p)), flush=True)
        if args.out:
            Path(args.out).write_text(json.dumps(raw, indent=1))
        return
    s = Settings()
    raw = {}
    for text in args.cases.split(","):
        case = parse_case(text)
        s_case = Settings(**{**s.__dict__, "t_pred": case.t_pred or s.t_pred})
        print(case.name)
        raw[case.name] = {}
        if args.framework in ("jax", "both"):
            raw[case.name]["jax"] = p = jax_profile(case, s_case, args.runs)
            print("\n".join(summary("jax", p)), flush=True)
        if args.framework in ("torch", "both"):
            raw[case.name]["torch"] = p = torch_profile(case, s_case, args.runs)
            print("\n".join(summary("torch", p)), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(raw, indent=1))


if __name__ == "__main__":
    main()
