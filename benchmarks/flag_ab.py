"""A/B of a process-wide setting (an XLA flag or an environment variable), one fresh process per measurement.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/flag_ab.py --flag=--xla_cpu_multi_thread_eigen=false \
        --cases dlow/train_cvae mojo/train_cvae divsamp/train_cvae --pairs 5          # ~5 min on the 2-core CPU
    flock /tmp/jaxmotion-heavy.lock python benchmarks/flag_ab.py \
        --env GLIBC_TUNABLES=glibc.malloc.hugetlb=1:glibc.malloc.mmap_max=0 --cases gsps/train_generator
    git clone -q . /tmp/base && flock /tmp/jaxmotion-heavy.lock python benchmarks/flag_ab.py \
        --base-tree /tmp/base --cases dlow/train_cvae --pairs 4     # a code change: this tree (B) against /tmp/base (A)

`benchmarks/ab.py` compares two settings inside one process; an XLA flag is read once, when jax starts,
so here each measurement is a fresh process (`--worker`) with `XLA_FLAGS` unset (A) or set to `--flag`
(B), in the order A, B, A, B, ... (`--pairs` pairs), and both with the huge-page tunable as the
`jaxmotion` command runs. With `--env NAME=VALUE` (repeatable) instead of, or besides, `--flag`,
B also sets those variables (a `GLIBC_TUNABLES` given here replaces A's, so include the huge-page
tunable in it where B should keep huge pages). Each worker builds the named cases of `benchmarks/run.py`'s plan with the
benchmark's own builders, warms them up twice and prints the median of `--repeats` calls. Prints the
per-pair figures and, per case, the median over pairs of A and of B and their ratio A / B (> 1: setting B
is faster). Writes `--out` (JSON) if given.

With `--base-tree DIR` (another checkout, e.g. a clone of the commit before a change), A's workers run
that checkout's code (its `benchmarks/flag_ab.py --worker`, which puts DIR first on the import path)
and B's this one, so a change to the library is measured the same way as a flag, in alternating fresh
processes; `--flag` / `--env` are then optional (when given they still apply to B only).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def worker(cases: list[str], repeats: int) -> dict[str, float]:
    """Returns `{case name: median ms}` for the plan's cases whose names start with one of `cases`."""
    from benchmarks.harness import Settings, measure, plan, reference_probe
    from benchmarks.jax_bench import Builders, matmul_probe

    base, out = Settings(), {}
    probe = matmul_probe(base.probe_n)
    ref = reference_probe(probe)
    for c in plan(base):
        if not any(c.name.startswith(p) for p in cases):
            continue
        run, _trace, _compile = getattr(Builders(base), c.model)(c)
        out[c.name] = measure(run, 2, repeats, probe, ref, base.slow_factor, base.probe_min_call_s)["median_s"] * 1e3
    if not out:
        raise SystemExit(f"flag_ab: no case of the plan starts with {cases}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--flag", default=None, help="the XLA flag of setting B, e.g. --flag=--xla_cpu_multi_thread_eigen=false")
    ap.add_argument("--env", action="append", default=[], metavar="NAME=VALUE", help="an environment variable of setting B")
    ap.add_argument("--cases", nargs="+", default=["dlow/train_cvae"], help="prefixes of benchmarks/run.py's case names")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=15, help="timed calls per case per worker")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--base-tree", type=Path, default=None, metavar="DIR",
                    help="setting A runs the code of this other checkout (B: this one)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.cases, args.repeats)))
        return 0
    if args.pairs < 1:
        ap.error(f"--pairs must be >= 1, got {args.pairs}")
    if args.flag is None and not args.env and args.base_tree is None:
        ap.error("give setting B: --flag and/or --env NAME=VALUE, or setting A's code: --base-tree DIR")
    if args.base_tree is not None and not (args.base_tree / "benchmarks" / "flag_ab.py").is_file():
        ap.error(f"--base-tree {args.base_tree}: no benchmarks/flag_ab.py there (give a checkout of this repository)")
    bad = [e for e in args.env if "=" not in e or not e.split("=", 1)[0]]
    if bad:
        ap.error(f"--env takes NAME=VALUE, got {bad}")
    extra = dict(e.split("=", 1) for e in args.env)
    label = " ".join([args.flag or ""] + args.env).strip() or "this tree"
    from benchmarks.harness import machine
    from jaxmotion.train.hugepages import with_tunable

    env0 = with_tunable({k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}, on=True)
    settings = {"A": env0, "B": {**env0, **({"XLA_FLAGS": args.flag} if args.flag else {}), **extra}}
    runs: dict[str, list[dict]] = {"A": [], "B": []}
    tail = ["--worker", "--repeats", str(args.repeats), "--cases", *args.cases]
    cmds = {lab: [sys.executable, str(Path(__file__).resolve()), *tail] for lab in ("A", "B")}
    if args.base_tree is not None:
        cmds["A"] = [sys.executable, str((args.base_tree / "benchmarks" / "flag_ab.py").resolve()), *tail]
    for i in range(args.pairs):
        for lab in ("A", "B"):
            res = subprocess.run(cmds[lab], env=settings[lab], capture_output=True, text=True)
            if res.returncode != 0:
                raise SystemExit(f"flag_ab: worker {lab} failed:\n{res.stderr[-2000:]}")
            runs[lab].append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(f"pair {i + 1} {lab}: " + ", ".join(f"{k} {v:.1f} ms" for k, v in runs[lab][-1].items()), flush=True)
    rows = []
    for case in runs["A"][0]:
        a = statistics.median(r[case] for r in runs["A"])
        b = statistics.median(r[case] for r in runs["B"])
        rows.append({"case": case, "A_ms": round(a, 2), "B_ms": round(b, 2), "ratio": round(a / b, 3)})
        print(f"{case:<32s} A {a:8.2f} ms  B ({label}) {b:8.2f} ms  A / B {a / b:.2f}x")
    if args.out:
        args.out.write_text(json.dumps({"machine": machine(), "flag": args.flag, "env": extra,
                                        "base_tree": str(args.base_tree) if args.base_tree else None, "a_env": {
                                            "GLIBC_TUNABLES": env0.get("GLIBC_TUNABLES", "")}, "pairs": args.pairs,
                                        "repeats": args.repeats, "rows": rows, "runs": runs}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
