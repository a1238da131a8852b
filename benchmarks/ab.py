"""A/B in one process: jaxmotion's training steps and K = 50 samplers under two settings of one knob.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py                          # --ab precision, ~6 min on the 2-core CPU
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab decoder_remat       # ~4 min
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab decoder_unroll      # ~4 min
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab decoder_backward    # ~4 min
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab gcn_node_major      # ~6 min
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab gsps_best_of        # ~3 min
    flock /tmp/jaxmotion-heavy.lock python benchmarks/ab.py --ab jax_host_devices    # ~3 min
    python benchmarks/ab.py --cases dlow/train_cvae --repeats 3                      # a subset

`--ab precision`: float32 against bfloat16 products (`Config.precision = "bf16"`,
jaxmotion/nn/precision.py rounds both operands of every weight product to bfloat16 and accumulates
in float32). `--ab decoder_remat`: the GRU decoders' backward pass stacking every intermediate of
every step against recomputing the gates' elementwise work (`Execution.decoder_remat`, DLow and MOJO).
`--ab decoder_unroll`: the same decoders' `lax.scan` loop rolled against unrolled 4 steps at a time
(`Execution.decoder_unroll`). Both shape the differentiated loop, so they run with
`decoder_backward="autodiff"`. `--ab decoder_backward`: that loop against the batched backward pass,
each weight's gradient one product after the loop (`Execution.decoder_backward`, nn/decoder_loop.py).
`--ab gcn_node_major`: DivSamp's and GSPS's graph-convolution stacks laid out batch-major
`(..., J, F)` against node-major `(J, ..., F)` inside (`Execution.gcn_node_major`, `nn/gcn.py` `GCLStack.node_major`).
`--ab gsps_best_of`: GSPS's best-of-K squared errors (against the truth and every pseudo future) by
differencing every pair against `|a|^2 + |m|^2 - 2 a.m` (`models/gsps.py` `generator_loss(best_of=...)`).
`--ab jax_host_devices`: the diffusion sampler on one device against its K samples split over two CPU host
devices (`models/diffusion.py` `sample(devices=...)`; the process starts jax with two forced host devices).
Each case of `benchmarks/run.py`'s plan named in `--cases` is built twice by the benchmark's own
builders (`jax_bench.Builders`, the same sizes and functions), once per setting, and the two are
timed alternately, `--rounds` rounds of `--repeats` calls each, so that drift in the machine's speed
falls on both. Prints the medians and the ratio A / B (> 1: B faster); for precision also whether
the CPU has bfloat16 instructions (without them the products are emulated). Writes
`benchmarks/results/<ab>_ab.json`. Figures count only from a quiet machine (hence the lock). What
bf16 does to the metrics is measured on trained Bandai-Namco-2 runs by
`benchmarks/eval_speed.py --precision float32 bf16 --noise-seed 1`.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import Settings, machine, plan  # noqa: E402
from benchmarks.peak import cpu_flags, has_bf16  # noqa: E402

# Each knob (a field of harness.Settings): its (A, B) values and their labels in the output.
KNOBS = {
    "precision": (("float32", "bf16"), ("float32", "bf16")),
    "decoder_remat": ((False, True), ("stacked", "remat")),
    "decoder_unroll": ((1, 4), ("rolled", "unroll 4")),
    "decoder_backward": (("autodiff", "batched"), ("autodiff", "batched")),
    "gcn_node_major": ((False, True), ("batch-major", "node-major")),
    "gsps_best_of": (("pairwise", "gram"), ("pairwise", "gram")),
    "jax_host_devices": ((1, 2), ("1-device", "2-devices")),
}
DEFAULT_CASES = {"precision": (
    "dlow/train_cvae/b64", "dlow/train_sampler/b16/k50", "dlow/sample/b64/k50",
    "mojo/train_cvae/b64", "mojo/sample/b64/k50",
    "divsamp/train_cvae/b64", "divsamp/train_sampler/b16/k50", "divsamp/sample/b64/k50",
    "gsps/sample/b64/k50",
), "decoder_remat": (  # the cases with a GRUCVAE decoder (the others do not change)
    "dlow/train_cvae/b64", "dlow/train_sampler/b16/k50", "dlow/sample/b64/k50",
    "mojo/train_cvae/b64", "mojo/train_sampler/b16/k50", "mojo/sample/b64/k50",
)}
DEFAULT_CASES["decoder_unroll"] = DEFAULT_CASES["decoder_remat"]
DEFAULT_CASES["decoder_backward"] = DEFAULT_CASES["decoder_remat"]
DEFAULT_CASES["gcn_node_major"] = (  # the cases with graph convolutions (DivSamp's and GSPS's)
    "divsamp/train_cvae/b64", "divsamp/train_sampler/b16/k50", "divsamp/sample/b64/k50",
    "gsps/train_generator", "gsps/sample/b64/k50",
)
DEFAULT_CASES["gsps_best_of"] = ("gsps/train_generator",)
DEFAULT_CASES["jax_host_devices"] = ("diffusion/sample_ddim/b1/k50/t60/s100", "diffusion/sample_ddim/b64/k50/t60/s10")


def _matches(name: str, patterns: list[str]) -> bool:
    return any(name == p or name.startswith(p + "/") for p in patterns)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ab", choices=sorted(KNOBS), default="precision", help="the knob to compare")
    ap.add_argument("--cases", nargs="+", default=None,
                    help="case names or prefixes of benchmarks/run.py's plan (e.g. dlow/train_cvae); default: the knob's cases")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds per case")
    ap.add_argument("--repeats", type=int, default=5, help="timed calls per setting per round")
    ap.add_argument("--out", type=Path, default=None, help="default: benchmarks/results/<ab>_ab.json")
    args = ap.parse_args(argv)
    values, labels = KNOBS[args.ab]
    args.cases = args.cases or list(DEFAULT_CASES[args.ab])
    args.out = args.out or ROOT / "benchmarks" / "results" / f"{args.ab}_ab.json"
    if args.ab == "jax_host_devices":  # the process needs the host devices before jax starts
        from jaxmotion.train.host_devices import host_device_flags

        os.environ["XLA_FLAGS"] = host_device_flags(os.environ.get("XLA_FLAGS", ""), max(values))
    import jax

    from benchmarks.jax_bench import Builders

    m = {**machine(), "bf16": has_bf16(cpu_flags())}
    base = Settings()
    if args.ab in ("decoder_remat", "decoder_unroll"):  # they shape the differentiated loop only
        base = dataclasses.replace(base, decoder_backward="autodiff")
    cases = [c for c in plan(base) if _matches(c.name.replace("/t60", ""), args.cases) or _matches(c.name, args.cases)]
    if not cases:
        raise SystemExit(f"ab: no case of the plan matches {args.cases}; names look like {plan(base)[0].name}")
    print(f"CPU: {m['cpu']}, {m['logical_cpus']} logical CPUs, bfloat16 instructions: {'yes' if m['bf16'] else 'no'}; "
          f"jax {jax.__version__}; {args.ab}: {labels[0]} (A) vs {labels[1]} (B); {args.rounds} rounds x {args.repeats} calls each")
    builders = {lab: Builders(dataclasses.replace(base, **{args.ab: v})) for lab, v in zip(labels, values)}
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
               "ratio": med[labels[0]] / med[labels[1]], **{f"{p}_compile_s": round(v, 2) for p, v in compile_s.items()}}
        rows.append(row)
        print(f"  {c.name:<32s} " + "  ".join(f"{lab} {row[lab + '_ms']:9.2f} ms" for lab in labels)
              + f"  ratio {row['ratio']:.2f}x", flush=True)
        del runs
        jax.clear_caches()
    print(f"ab {args.ab}: {time.perf_counter() - t_start:.0f} s")
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": m,
           "command": "python benchmarks/ab.py " + " ".join(sys.argv[1:] if argv is None else argv), "ab": args.ab,
           "rounds": args.rounds, "repeats": args.repeats, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
