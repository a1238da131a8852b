"""A/B in one process: jaxmotion's training steps and K = 50 samplers with float32 and with bfloat16 products.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/precision_ab.py            # ~6 min on the 2-core CPU
    python benchmarks/precision_ab.py --cases dlow/train_cvae --repeats 3        # a subset

`Config.precision = "bf16"` (jaxmotion/nn/precision.py) rounds both operands of every weight product
to bfloat16 and accumulates in float32. Each case of `benchmarks/run.py`'s plan named in `--cases` is
built twice by the benchmark's own builders (`jax_bench.Builders`, the same sizes and functions),
once per precision, and the two are timed alternately, `--rounds` rounds of `--repeats` calls each,
so that drift in the machine's speed falls on both. Prints the medians, the ratio float32 / bf16
(> 1: bf16 faster) and whether the CPU has bfloat16 instructions; without them the products are
emulated and the ratio says so. Writes `benchmarks/results/precision_ab.json`. Figures count only
from a quiet machine (hence the lock). What bf16 does to the metrics is measured on trained
Bandai-Namco-2 runs by `benchmarks/eval_speed.py --precision float32 bf16 --noise-seed 1`.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import Settings, machine, plan  # noqa: E402
from benchmarks.peak import cpu_flags, has_bf16  # noqa: E402

DEFAULT_CASES = (
    "dlow/train_cvae/b64", "dlow/train_sampler/b16/k50", "dlow/sample/b64/k50",
    "mojo/train_cvae/b64", "mojo/sample/b64/k50",
    "divsamp/train_cvae/b64", "divsamp/train_sampler/b16/k50", "divsamp/sample/b64/k50",
    "gsps/sample/b64/k50",
)


def _matches(name: str, patterns: list[str]) -> bool:
    return any(name == p or name.startswith(p + "/") for p in patterns)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES),
                    help="case names or prefixes of benchmarks/run.py's plan (e.g. dlow/train_cvae)")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds per case")
    ap.add_argument("--repeats", type=int, default=5, help="timed calls per precision per round")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "precision_ab.json")
    args = ap.parse_args(argv)
    import jax

    from benchmarks.jax_bench import Builders

    m = {**machine(), "bf16": has_bf16(cpu_flags())}
    base = Settings()
    cases = [c for c in plan(base) if _matches(c.name.replace("/t60", ""), args.cases) or _matches(c.name, args.cases)]
    if not cases:
        raise SystemExit(f"precision_ab: no case of the plan matches {args.cases}; names look like {plan(base)[0].name}")
    print(f"CPU: {m['cpu']}, {m['logical_cpus']} logical CPUs, bfloat16 instructions: {'yes' if m['bf16'] else 'no'}; "
          f"jax {jax.__version__}; {args.rounds} rounds x {args.repeats} calls per precision")
    builders = {p: Builders(dataclasses.replace(base, precision=p)) for p in ("float32", "bf16")}
    rows, t_start = [], time.perf_counter()
    for c in cases:
        runs, compile_s = {}, {}
        for p, b in builders.items():
            run, _trace, compile_s[p] = getattr(b, c.model)(c)
            run()  # warm-up
            runs[p] = run
        times = {p: [] for p in runs}
        for _ in range(args.rounds):
            for p, run in runs.items():
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    run()
                    times[p].append(time.perf_counter() - t0)
        med = {p: statistics.median(t) for p, t in times.items()}
        row = {"case": c.name, **{f"{p}_ms": round(v * 1e3, 3) for p, v in med.items()},
               "ratio": med["float32"] / med["bf16"], **{f"{p}_compile_s": round(v, 2) for p, v in compile_s.items()}}
        rows.append(row)
        print(f"  {c.name:<32s} float32 {row['float32_ms']:9.2f} ms  bf16 {row['bf16_ms']:9.2f} ms  "
              f"ratio {row['ratio']:.2f}x", flush=True)
        del runs
        jax.clear_caches()
    print(f"precision_ab: {time.perf_counter() - t_start:.0f} s")
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": m,
           "command": "python benchmarks/precision_ab.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "rounds": args.rounds, "repeats": args.repeats, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
