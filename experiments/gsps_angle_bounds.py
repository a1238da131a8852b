"""GSPS's joint-angle bounds measured on HumanEva-I's training poses, beside the GSPS supplementary's.

    python experiments/gsps_angle_bounds.py --data /path/to/data_3d_humaneva15.npz [--out experiments/results/humaneva]

HumanEva-I is licensed: the file is read from `--data` and nothing of its frames is written, only the
bounds. Without the file the script says so and exits 0.

A GSPS run measures its bounds with `jaxmotion.models.gsps.measure_angle_bounds` on `angle_bounds_frames`
evenly spaced training frames: the `angle_percentile` and `100 - angle_percentile` percentiles of each
cosine, widened by `angle_margin`. Those numbers are written for every library angle, as cosines and as
angles in degrees, with the un-widened percentiles and the full range over every training frame.

The supplementary gives three HumanEva-I ranges under its own names; the library's angles are defined
from joint roles (after the release's Human3.6M check), so each is set beside the nearest library angle:
Neck2Spine (head-thorax against thorax-root) is `Head2Neck`; Leg2ThighPlane (the shank against the
hip-thigh plane's normal, the knee's bending) is `Leg2HipPlane_l` / `_r`; Thigh2TorsoPlane is compared
with the knee-from-root direction's angle to the shoulder-root plane (90 degrees minus its angle to the
plane's normal, `Leg2ShoulderPlane_l` / `_r`), the nearest library angle to a thigh against the torso
plane. The definitions differ; the comparison says whether the measured ranges are of the same size.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

SUPPLEMENTARY = {  # GSPS supplementary, HumanEva-I, degrees
    "Neck2Spine": ((0.0, 50.0), ("Head2Neck",), "angle"),
    "Leg2ThighPlane": ((72.0, 166.0), ("Leg2HipPlane_l", "Leg2HipPlane_r"), "angle"),
    "Thigh2TorsoPlane": ((0.0, 58.0), ("Leg2ShoulderPlane_l", "Leg2ShoulderPlane_r"), "to_plane"),
}


def degrees(cos_lo: float, cos_hi: float, kind: str = "angle") -> tuple[float, float]:
    """Returns the angle range `(min, max)` in degrees of cosines in `[cos_lo, cos_hi]`: the angle itself,
    or (`kind="to_plane"`) 90 degrees minus it, the angle to the plane whose normal the cosine is taken with."""
    a = np.degrees(np.arccos(np.clip([cos_hi, cos_lo], -1.0, 1.0)))
    if kind == "to_plane":
        a = np.sort(90.0 - a)
    return round(float(a[0]), 1), round(float(a[1]), 1)


def measure(path: Path) -> dict:
    """Returns the bounds record of the training poses of the HumanEva-I file at `path`."""
    from jaxmotion.data.datasets import load_humaneva
    from jaxmotion.data.windows import sequence_frames
    from jaxmotion.methods.gsps import bounds_frames
    from jaxmotion.models import gsps
    from jaxmotion.models.gsps import GSPSConfig

    ds = load_humaneva(path)
    c = GSPSConfig()
    names, parents = tuple(ds.skeleton.names), tuple(int(p) for p in ds.skeleton.parents)
    roles = gsps.angle_roles(names, parents)
    train = sequence_frames(ds.train)
    frames = bounds_frames(train, c.angle_bounds_frames)
    run = gsps.measure_angle_bounds(frames, roles, c.angle_percentile, c.angle_margin)
    raw = gsps.measure_angle_bounds(frames, roles, c.angle_percentile, 0.0)
    allcos = np.asarray(gsps.angle_cosines(np.concatenate(train), roles))
    angles = {}
    for i, name in enumerate(gsps.ANGLE_NAMES):
        lo, hi = float(allcos[:, i].min()), float(allcos[:, i].max())
        angles[name] = {
            "run_cos": [round(float(run[i, 0]), 4), round(float(run[i, 1]), 4)],
            "run_deg": degrees(run[i, 0], run[i, 1]),
            "percentile_cos": [round(float(raw[i, 0]), 4), round(float(raw[i, 1]), 4)],
            "percentile_deg": degrees(raw[i, 0], raw[i, 1]),
            "full_range_deg": degrees(lo, hi),
        }
    comparison = []
    for sup, (rng, ours, kind) in SUPPLEMENTARY.items():
        for name in ours:
            i = gsps.ANGLE_NAMES.index(name)
            lo, hi = float(allcos[:, i].min()), float(allcos[:, i].max())
            comparison.append({
                "supplementary": sup, "supplementary_deg": list(rng), "library_angle": name, "measured_as": kind,
                "run_deg": degrees(run[i, 0], run[i, 1], kind), "percentile_deg": degrees(raw[i, 0], raw[i, 1], kind),
                "full_range_deg": degrees(lo, hi, kind),
                # The plane's normal taken the other way round: 180 degrees minus the angle.
                "percentile_deg_other_normal": degrees(-raw[i, 1], -raw[i, 0], kind),
            })
    return {
        "dataset": "HumanEva-I (VideoPose3D data_3d_humaneva15.npz), training split Train/S1-S3 after the releases' dropped takes",
        "training_frames": int(sum(len(f) for f in train)),
        "frames_measured": int(len(frames)),
        "measured": f"percentiles {c.angle_percentile} / {100 - c.angle_percentile} of the cosines over "
                    f"{len(frames)} evenly spaced training frames (run_*: widened by {c.angle_margin} in cosine, as a "
                    "GSPS run does; percentile_*: not widened); full_range_deg: min / max over every training frame",
        "comparison": comparison,
        "angles": angles,
    }


def markdown(rec: dict) -> str:
    """Returns the short table: the supplementary's three ranges beside the nearest library angles."""
    lines = [
        "# GSPS's angle bounds on HumanEva-I: measured against the supplementary",
        "",
        f"Measured by `python experiments/gsps_angle_bounds.py` on {rec['frames_measured']:,} evenly spaced of the "
        f"{rec['training_frames']:,} training frames (Train/S1-S3), with the library's `measure_angle_bounds` "
        "(0.1th / 99.9th percentiles; a GSPS run widens them by 0.05 in cosine). Degrees.",
        "",
        "| supplementary | its range | library angle (nearest) | percentiles | as a run uses them | every training frame "
        "| percentiles, the plane's normal reversed |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    fmt = lambda r: f"{r[0]:.0f} to {r[1]:.0f}"  # noqa: E731
    for c in rec["comparison"]:
        how = " (to the plane)" if c["measured_as"] == "to_plane" else ""
        lines.append(f"| {c['supplementary']} | {fmt(c['supplementary_deg'])} | `{c['library_angle']}`{how} | "
                     f"{fmt(c['percentile_deg'])} | {fmt(c['run_deg'])} | {fmt(c['full_range_deg'])} | "
                     f"{fmt(c['percentile_deg_other_normal'])} |")
    lines += [
        "",
        "Signed angles to a plane are negative on the side opposite the normal. Which way a normal points is a",
        "convention (the order of a cross product): the last column takes it the other way round (180 degrees",
        "minus the angle; for an angle to the plane, its negative).",
        "",
        "The library's angles are defined from joint roles after the release's Human3.6M check, not the",
        "supplementary's HumanEva-I set, so the rows compare ranges of the nearest definitions, not the same angles.",
        "Every library angle's bounds (cosines and degrees): `gsps_angle_bounds.json`.",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path.home() / "data" / "data_3d_humaneva15.npz"), help="data_3d_humaneva15.npz")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "humaneva"), help="output folder")
    args = ap.parse_args(argv)
    path = Path(args.data).expanduser()
    if not path.is_file():
        print(f"gsps_angle_bounds: no HumanEva-I file at {path} (it is licensed; pass --data PATH); nothing measured")
        return 0
    rec = measure(path)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "gsps_angle_bounds.json").write_text(json.dumps(rec, indent=1) + "\n")
    (out / "gsps_angle_bounds.md").write_text(markdown(rec))
    print(markdown(rec))
    return 0


if __name__ == "__main__":
    sys.exit(main())
