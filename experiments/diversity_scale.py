"""The diversity settings `jaxmotion.diversity`'s rule gives a dataset, beside the releases' own.

    python experiments/diversity_scale.py --data ../shared/data/bandai-namco-2
    python experiments/diversity_scale.py --data synthetic

Measures the future spread `s` (the zero-velocity ADE) on the dataset's training windows (every
`t_his` frames of every training sequence; the test split is not read for it), then prints DLow's
`d_scale` and GSPS's `alpha` / `beta` (lower body, then the rest) from the rule, and the same rule
applied to the releases' documented spreads next to the values the releases use.
"""

from __future__ import annotations

import argparse
import dataclasses

from jaxmotion import diversity
from jaxmotion.config import Config
from jaxmotion.data.windows import sequence_frames, test_windows
from jaxmotion.experiment import load_data
from jaxmotion.models import gsps


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="synthetic", help="'synthetic' or a dataset path")
    args = ap.parse_args(argv)
    ds = load_data(dataclasses.replace(Config(), dataset=args.data))
    windows, _, _ = test_windows(sequence_frames(ds.train), ds.t_his, ds.t_pred)
    s = diversity.future_spread(windows, ds.t_his)
    first, rest = gsps.body_parts(ds.skeleton.names, ds.skeleton.parents, "lower_upper")
    rows = [(f"{ds.name} (measured, {len(windows)} training windows)", ds.t_pred, ds.dim, 3 * len(first), 3 * len(rest), s, None)]
    rows += [(f"{r.dataset} (release)", r.t_pred, r.dim, r.coords_first, r.coords_rest, r.spread, r) for r in diversity.RELEASES]
    print("| dataset | t_pred | D | part coords | spread s (m) | DLow d_scale: rule (release) | GSPS alpha: rule (release) | GSPS beta: rule (release) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, t_pred, dim, cf, cr, sp, rel in rows:
        d = diversity.dlow_d_scale(sp, t_pred, dim)
        a, b = diversity.gsps_alphas(sp, t_pred, dim, cf, cr)
        given = (lambda v: f" ({v:g})") if rel else (lambda v: "")
        print(
            f"| {name} | {t_pred} | {dim} | {cf} + {cr} | {sp:.3f} | {d:.1f}{given(rel and rel.d_scale)} | "
            f"{a:.1f}{given(rel and rel.alpha)} | {b:.1f}{given(rel and rel.beta)} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
