"""C3D reader: the real Vicon files (labels, units, gaps) and clear errors on bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jaxmotion.formats.c3d import read_c3d

C3D_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vicon-c3d"
needs_data = pytest.mark.skipif(not C3D_DIR.is_dir(), reason=f"{C3D_DIR} absent (../shared/data not mounted)")


@needs_data
@pytest.mark.parametrize("name, frames, seen", [("squat.c3d", 2539, 0.98), ("nick_freeform_001.c3d", 1101, 0.93)])
def test_real_vicon_files(name, frames, seen):
    rec = read_c3d(C3D_DIR / name)
    assert rec.points.shape == (frames, 53, 3) and rec.mask.shape == (frames, 53)
    assert rec.rate == 120.0 and rec.units == "mm"
    assert rec.labels[:5] == ("ARIEL", "LFHD", "LBHD", "RFHD", "RBHD") and rec.raw_labels[0].endswith(":ARIEL")
    assert {"LHEL", "RHEL", "LFWT", "C7", "CLAV", "LTOE"} <= set(rec.labels)
    assert abs(rec.mask.mean() - seen) < 0.01  # the README's 98% / 93% of samples present
    assert np.all(np.isnan(rec.points[~rec.mask])) and np.all(np.isfinite(rec.points[rec.mask]))
    # Metres: the head-top marker of a standing adult is 1.4-2.0 m from the feet markers.
    heights = np.nanmedian(rec.points[:, rec.labels.index("ARIEL")] - rec.points[:, rec.labels.index("LHEL")], 0)
    assert 1.3 < np.max(np.abs(heights)) < 2.0
    pts, msk = rec.select(("C7", "NOPE"))
    assert pts.shape == (frames, 2, 3) and not msk[:, 1].any()


@needs_data
def test_truncated_file_is_a_clear_error(tmp_path):
    data = (C3D_DIR / "squat.c3d").read_bytes()
    bad = tmp_path / "cut.c3d"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=r"cut\.c3d.*truncated"):
        read_c3d(bad)


def test_not_a_c3d_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "noise.c3d"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes().replace(b"P", b"Q"))
    with pytest.raises(ValueError, match=r"noise\.c3d: not a C3D file"):
        read_c3d(bad)
    with pytest.raises(FileNotFoundError, match="missing.c3d"):
        read_c3d(tmp_path / "missing.c3d")
