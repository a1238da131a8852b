"""Two `benchmarks/run.py` results files side by side: every case's median per framework, and the ratio A / B.

    python benchmarks/compare_runs.py benchmarks/results/A.json benchmarks/results/B.json [--markdown]

For an A/B that cannot be made in one process (a setting read at process start, such as
`run.py --hugepages on|off`), run `run.py` twice, back to back on a quiet machine, and compare the
files here. Ratio > 1: B faster. The two files must come from the same CPU (checked).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def _ms(rec: dict | None) -> float | None:
    return None if rec is None else 1000.0 * rec["median_s"]


def compare(a: dict, b: dict) -> list[dict]:
    """Returns one row per case present in both: `{"case", fw: (ms_a, ms_b, a / b) ...}`."""
    if a["machine"]["cpu"] != b["machine"]["cpu"]:
        raise SystemExit(f"compare_runs: different CPUs ({a['machine']['cpu']!r} vs {b['machine']['cpu']!r}): no ratio")
    rows_b = {r["case"]: r for r in b["rows"]}
    out = []
    for ra in a["rows"]:
        rb = rows_b.get(ra["case"])
        if rb is None:
            continue
        row = {"case": ra["case"]}
        for fw in ("jax", "torch_eager", "torch_compile"):
            ta, tb = _ms(ra.get(fw)), _ms(rb.get(fw))
            if ta is not None and tb is not None:
                row[fw] = (ta, tb, ta / tb)
        out.append(row)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    args = ap.parse_args(argv)
    a, b = (json.loads(p.read_text()) for p in (args.a, args.b))
    rows = compare(a, b)
    fws = [fw for fw in ("jax", "torch_eager", "torch_compile") if any(fw in r for r in rows)]
    print(f"A: {args.a} ({a['date']}, `{a['command']}`)\nB: {args.b} ({b['date']}, `{b['command']}`)\nCPU: {a['machine']['cpu']}\n")
    if args.markdown:
        print("| case | " + " | ".join(f"{fw} ms A | {fw} ms B | A / B" for fw in fws) + " |")
        print("| --- |" + " --- | --- | --- |" * len(fws))
    for r in rows:
        cells = []
        for fw in fws:
            ta, tb, q = r.get(fw, (None, None, None))
            cells += ["-", "-", "-"] if q is None else [f"{ta:.1f}", f"{tb:.1f}", f"{q:.2f}x"]
        if args.markdown:
            print(f"| {r['case']} | " + " | ".join(cells) + " |")
        else:
            print(f"{r['case']:<40s} " + "  ".join(cells))


if __name__ == "__main__":
    main()
