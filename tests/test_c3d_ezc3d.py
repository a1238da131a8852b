"""jaxmotion's C3D reader against ezc3d (the maintained C3D library, `pip install ezc3d`).

Same labels, rate, units, gaps and points (metres) on the shared Vicon files, on files ezc3d writes
(more than 255 points through POINT:LABELS2, analog channels, POINT:UNITS never set), on integer
and DEC files written here (ezc3d writes only Intel floats; it does not read MIPS files, which are
checked against the values written), and on a trial of 70,000 frames.
Skipped when ezc3d is not installed (the `c3d` extra).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from jaxmotion.formats.c3d import read_c3d

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests/, for the C3D writer
from c3d_files import c3d_file  # noqa: E402

ezc3d = pytest.importorskip("ezc3d", reason="ezc3d not installed (pip install -e '.[c3d]'): no reference C3D reader")

C3D_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vicon-c3d"
UNIT = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "": 1e-3}
TOL = 5e-7  # metres: float32 rounding of coordinates of a few metres


def ezc3d_view(path: Path):
    """Returns `(raw labels, points (F, M, 3) m, mask (F, M), rate, units)` of `path` as ezc3d reads it."""
    c = ezc3d.c3d(str(path))
    p = c["parameters"]["POINT"]
    labels = list(p["LABELS"]["value"])
    i = 2
    while f"LABELS{i}" in p:
        labels += list(p[f"LABELS{i}"]["value"])
        i += 1
    xyz = c["data"]["points"][:3].transpose(2, 1, 0)
    res = c["data"]["meta_points"]["residuals"][0].T
    units = (list(p["UNITS"]["value"]) or [""])[0].lower() if "UNITS" in p else ""
    mask = np.isfinite(xyz).all(-1) & (res >= 0)
    return tuple(labels[: xyz.shape[1]]), xyz * UNIT[units], mask, float(p["RATE"]["value"][0]), units or "mm"


def assert_same(path: Path):
    rec = read_c3d(path)
    labels, points, mask, rate, units = ezc3d_view(path)
    assert rec.raw_labels == labels and (rec.rate, rec.units) == (rate, units)
    assert rec.mask.shape == mask.shape and np.array_equal(rec.mask, mask)
    np.testing.assert_allclose(rec.points[mask], points[mask], atol=TOL, rtol=0)
    return rec


@pytest.mark.skipif(not C3D_DIR.is_dir(), reason=f"{C3D_DIR} absent (../shared/data not mounted)")
@pytest.mark.parametrize("name", ["squat.c3d", "nick_freeform_001.c3d"])
def test_shared_vicon_files_read_as_ezc3d_reads_them(name):
    rec = assert_same(C3D_DIR / name)
    assert rec.mask.mean() > 0.9 and len(rec.labels) == 53


def ezc3d_file(path: Path, m: int, f: int, *, units: str | None = "mm", analogs: int = 0, ratio: int = 1, seed: int = 0):
    """Writes with ezc3d `m` points (`Subj:M000`...) over `f` frames at 100 Hz, 5% of them gaps."""
    rng = np.random.default_rng(seed)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"Subj:M{i:03d}" for i in range(m))
    if units is not None:
        c.add_parameter("POINT", "UNITS", [units])
    pts = np.ones((4, m, f))
    pts[:3] = rng.normal(0, 500, (3, m, f))
    gaps = rng.random((m, f)) < 0.05
    pts[:3, gaps] = np.nan
    c["data"]["points"] = pts
    if analogs:
        c["parameters"]["ANALOG"]["RATE"]["value"] = [100.0 * ratio]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = tuple(f"EMG{i}" for i in range(analogs))
        c["data"]["analogs"] = rng.normal(0, 1, (1, analogs, f * ratio))
    c.write(str(path))
    return pts, gaps


@pytest.mark.parametrize(
    "case, kw",
    [("labels2_300_points", dict(m=300, f=12)), ("analog_3_channels_x4", dict(m=4, f=25, analogs=3, ratio=4)),
     ("units_never_set", dict(m=3, f=10, units=None))],
)  # fmt: skip
def test_files_ezc3d_writes(tmp_path, case, kw):
    path = tmp_path / f"{case}.c3d"
    pts, gaps = ezc3d_file(path, **kw)
    rec = assert_same(path)
    assert rec.points.shape == (kw["f"], kw["m"], 3) and np.array_equal(rec.mask, ~gaps.T)
    np.testing.assert_allclose(rec.points[rec.mask], pts[:3].transpose(2, 1, 0)[rec.mask] * 1e-3, atol=TOL, rtol=0)
    assert rec.labels[-1] == f"M{kw['m'] - 1:03d}" and rec.raw_labels[0] == "Subj:M000"


@pytest.mark.parametrize("proc", [84, 85, 86], ids=["intel", "dec", "mips"])
@pytest.mark.parametrize("scale", [-0.1, 0.1], ids=["float", "int16"])
def test_processor_types_and_integer_storage(tmp_path, proc, scale):
    rng = np.random.default_rng(proc)
    pts = rng.normal(0, 800, (30, 5, 3)).round(1).astype(np.float32)
    res = np.where(rng.random((30, 5)) < 0.15, -1.0, 3.0).astype(np.float32)
    path = tmp_path / "trial.c3d"
    path.write_bytes(c3d_file(pts, res, [f"S:P{i}" for i in range(5)], proc=proc, scale=scale))
    # ezc3d 1.7.2 raises "MIPS processor type not supported yet": MIPS is checked against the values written.
    rec = assert_same(path) if proc != 86 else read_c3d(path)
    assert rec.rate == 60.0 and rec.units == "mm" and rec.labels == ("P0", "P1", "P2", "P3", "P4")
    assert np.array_equal(rec.mask, res >= 0)
    # int16 steps of 0.1 mm hold these values exactly; floats round to float32.
    np.testing.assert_allclose(rec.points[rec.mask], pts[res >= 0] * 1e-3, atol=TOL, rtol=0)


def test_trial_past_65535_frames(tmp_path):
    f = 70_000
    path = tmp_path / "long.c3d"
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("S:A", "S:B")
    c.add_parameter("POINT", "UNITS", ["mm"])
    pts = np.ones((4, 2, f))
    pts[:3] = np.arange(6 * f).reshape(3, 2, f) % 1000
    c["data"]["points"] = pts
    # ezc3d saturates POINT:FRAMES and the header at 65,535; Vicon's TRIAL fields carry the count.
    for name, v in (("ACTUAL_START_FIELD", 1), ("ACTUAL_END_FIELD", f)):
        prm = ezc3d.ezc3d.Parameter(name)
        prm.set(ezc3d.ezc3d.VecInt([v & 0xFFFF, v >> 16]), [2])
        c._storage["parameters"].add_parameter("TRIAL", prm)
    c.write(str(path))
    rec = read_c3d(path)
    assert rec.points.shape == (f, 2, 3) and rec.mask.all()
    np.testing.assert_allclose(rec.points, pts[:3].transpose(2, 1, 0) * 1e-3, atol=TOL, rtol=0)
    _, ez, _, _, _ = ezc3d_view(path)  # ezc3d 1.7.2 stops at frame 65,535: compare what it reads
    n = min(len(ez), f)
    np.testing.assert_allclose(rec.points[:n], ez[:n], atol=TOL, rtol=0)
