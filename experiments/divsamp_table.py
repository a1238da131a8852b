"""The DivSamp comparison table on Bandai-Namco-2 (K = 50, shared budget) from two metrics.json files.

    python experiments/divsamp_table.py --divsamp /tmp/runs/divsamp_bandai/metrics.json \
        --dlow /tmp/runs/dlow_bandai/metrics.json --out experiments/results/divsamp_bandai_table.md

Rows: DivSamp and its CVAE sampled from N(0, I) (from the DivSamp run), DLow, DLow's CVAE from
N(0, I) and zero-velocity (from the DLow run). Prints the markdown table and whether the paper's
ordering holds (DivSamp more diverse than DLow at equal or better ADE/FDE).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

KEYS = ["APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m"]
LABELS = {
    "divsamp": "DivSamp (GCN CVAE + Gumbel-Softmax sampler)",
    "divsamp_cvae": "DivSamp's GCN CVAE, z ~ N(0, I)",
    "dlow": "DLow (GRU CVAE + Q network)",
    "cvae": "DLow's GRU CVAE, z ~ N(0, I)",
    "zero_velocity": "zero-velocity",
}


def rows(path: Path, methods: list[str], k: int) -> list[dict]:
    recs = json.loads(Path(path).read_text())
    out = [r for r in recs if r["method"] in methods and r["K"] == k]
    missing = set(methods) - {r["method"] for r in out}
    if missing:
        raise SystemExit(f"{path}: no K={k} record for {sorted(missing)}")
    return sorted(out, key=lambda r: methods.index(r["method"]))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--divsamp", required=True)
    p.add_argument("--dlow", required=True)
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    recs = rows(args.divsamp, ["divsamp", "divsamp_cvae"], args.k) + rows(args.dlow, ["dlow", "cvae", "zero_velocity"], args.k)
    lines = ["| method | " + " | ".join(KEYS) + " |", "| --- |" + " --- |" * len(KEYS)]
    for r in recs:
        lines.append(f"| {LABELS[r['method']]} | " + " | ".join(f"{r['metrics'][k]:.3f}" for k in KEYS) + " |")
    m = {r["method"]: r["metrics"] for r in recs}
    ds, dl = m["divsamp"], m["dlow"]
    holds = ds["APD"] > dl["APD"] and ds["ADE"] <= dl["ADE"] and ds["FDE"] <= dl["FDE"]
    verdict = (
        f"Paper's ordering (DivSamp more diverse than DLow at equal or better ADE/FDE): "
        f"{'holds' if holds else 'does not hold'} (APD {ds['APD']:.3f} vs {dl['APD']:.3f}, "
        f"ADE {ds['ADE']:.3f} vs {dl['ADE']:.3f}, FDE {ds['FDE']:.3f} vs {dl['FDE']:.3f})."
    )
    text = "\n".join(lines) + "\n\n" + verdict + "\n"
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
