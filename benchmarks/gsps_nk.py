"""GSPS's generator training step at nk1 x nk2 = 5 x 5 (the Bandai configs) and 10 x 10 (the release's), one process.

    flock /tmp/jaxmotion-heavy.lock python -m benchmarks.gsps_nk --out benchmarks/results/gsps_nk_cpu.json

Times the real training step (`gsps.generator_loss` with the optimiser, batch 16 windows of
Bandai-Namco-2's shape, 10 pseudo futures each; `jax_bench.Builders.gsps`) for both sample grids
back to back, and prints the time per step, the time per sampled future and the ratio, all from
this one run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from benchmarks.harness import Case, Settings, machine, measure
from benchmarks.jax_bench import Builders


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = []
    for nk in ((5, 5), (10, 10), (5, 5)):  # 5 x 5 again last: the machine's drift shows in its two figures
        s = dataclasses.replace(Settings(), gsps_nk=nk)
        case = Case("gsps", "train_generator", s.sampler_batch, k=nk[0] * nk[1], t_pred=s.t_pred)
        run, _, compile_s = Builders(s).gsps(case)
        r = measure(run, args.warmup, args.repeats)
        rows.append({"nk1": nk[0], "nk2": nk[1], "median_ms": r["median_s"] * 1e3, "min_ms": r["min_s"] * 1e3, "compile_s": compile_s})
        print(f"GSPS generator step, nk {nk[0]} x {nk[1]}, batch {s.sampler_batch}: {r['median_s'] * 1e3:.1f} ms median "
              f"({r['median_s'] * 1e3 / (nk[0] * nk[1]):.2f} ms per sampled future)", flush=True)
    five = min(rows[0]["median_ms"], rows[2]["median_ms"])
    ratio = rows[1]["median_ms"] / five
    print(f"10 x 10 costs {ratio:.2f}x the 5 x 5 step (4x the samples)")
    if args.out:
        args.out.write_text(json.dumps({"machine": machine(), "rows": rows, "ratio_10x10_over_5x5": ratio}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
