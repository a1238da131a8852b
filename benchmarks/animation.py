"""The futures' animation (`pictures.animate.animate_futures`, the GIF of `jaxmotion run` and `jaxmotion predict`)
of this tree against the same function at another git revision, in one process.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/animation.py --base REV   # about a minute on the 2-core CPU

Both draw the same window (the synthetic data's first test window, its future jittered K times) to a GIF,
alternately, `--rounds` times each; prints each one's fastest call (the first round is a warm-up and not
counted), the ratio base / this tree (> 1: this tree faster) and whether the two files are byte-identical,
and writes `benchmarks/results/animation.json`.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine  # noqa: E402

MODULE = "jaxmotion/pictures/animate.py"


def _module_at(rev: str, folder: Path):
    """Imports `MODULE` as it is at git revision `rev` (it imports the rest of jaxmotion from this tree)."""
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{MODULE}"], capture_output=True, text=True)
    if src.returncode != 0:
        sys.exit(f"error: git cannot show {MODULE} at {rev!r}: {src.stderr.strip()}")
    path = folder / "animate_base.py"
    path.write_text(src.stdout)
    spec = importlib.util.spec_from_file_location("animate_base", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="git revision whose animate_futures is the baseline")
    ap.add_argument("--k", default="10,50", help="numbers of futures drawn, comma-separated")
    ap.add_argument("--rounds", type=int, default=4, help="calls of each, alternating (the first is a warm-up)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "animation.json"))
    args = ap.parse_args(argv)
    if args.rounds < 2:
        sys.exit("error: --rounds must be at least 2 (the first round is a warm-up)")

    from jaxmotion.data.synthetic import make_synthetic
    from jaxmotion.pictures import animate

    ds = make_synthetic(0)
    pos = ds.test[0].positions
    x, gt = pos[: ds.t_his], pos[ds.t_his : ds.t_his + ds.t_pred]
    rng = np.random.default_rng(0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        sides = {"base": _module_at(args.base, folder), "this tree": animate}
        for k in (int(v) for v in args.k.split(",")):
            preds = gt + 0.01 * rng.normal(size=(k, *gt.shape))
            times = {name: [] for name in sides}
            for _ in range(args.rounds):
                for name, mod in sides.items():
                    t0 = time.perf_counter()
                    mod.animate_futures(x, preds, gt, ds.skeleton.parents, folder / f"{name}.gif", fps=ds.fps, joints=True)
                    times[name].append(time.perf_counter() - t0)
            best = {name: min(t[1:]) for name, t in times.items()}
            same = (folder / "base.gif").read_bytes() == (folder / "this tree.gif").read_bytes()
            row = {"K": k, "base_s": round(best["base"], 3), "this_tree_s": round(best["this tree"], 3),
                   "ratio": round(best["base"] / best["this tree"], 2), "byte_identical": same}
            rows.append(row)
            print(f"K = {k}: base {row['base_s']:.2f} s, this tree {row['this_tree_s']:.2f} s, {row['ratio']:.2f}x; "
                  f"the GIFs are {'byte-identical' if same else 'DIFFERENT'}")
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": machine(),
           "command": "python benchmarks/animation.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "base": args.base, "rounds": args.rounds, "rows": rows}
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
