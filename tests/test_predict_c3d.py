"""C3D input for marker models (`jaxmotion predict`): labels, short gaps filled, long gaps named, MOJO's canonical frame.

The C3D files are fabricated from the built-in `bandai` body (so the joints are known) and the
model's layout is the one training writes for such a marker dataset (`predictor.layout`); a MOJO
model is not trained here (its compilation takes over a minute on two cores).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxmotion.body.markersets import MARKER_SETS
from jaxmotion.body.skeleton import toy_skeleton
from jaxmotion.data.markers import canonicalise, marker_skeleton
from jaxmotion.data.types import MotionDataset
from jaxmotion.errors import DataError
from jaxmotion.tools.predict_file import read_motion
from jaxmotion.tools.predict_markers import fill_gaps, marker_window
from jaxmotion.tools.predictor import layout

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests/, for the C3D writer
from c3d_files import c3d_file  # noqa: E402

BODY = toy_skeleton("bandai")
T_HIS, T_PRED = 6, 8
C3D_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vicon-c3d"


def lay() -> dict:
    ds = MotionDataset("toy_markers", marker_skeleton(BODY.marker_names), 30.0, T_HIS, T_PRED, 0.5, [], [], info={"frames": "global", "up_axis": 2})
    return layout(ds)


@pytest.fixture(scope="module")
def walk():
    """Returns `(markers, joints)` (80, ., 3) at 30 fps, Y up, of the body walking and moving its limbs."""
    rng = np.random.default_rng(5)
    n = 80
    p = BODY.zero_params()
    rep = lambda a: jnp.broadcast_to(a, (n,) + a.shape)  # noqa: E731
    params = p._replace(
        transl=rep(p.transl) + jnp.asarray(np.cumsum(0.02 * rng.standard_normal((n, 3)), 0) * [1.0, 0.0, 1.0], jnp.float32),
        orient=rep(p.orient), shape=rep(p.shape), hand=rep(p.hand),
        pose=jnp.asarray(np.cumsum(0.05 * rng.standard_normal((n, p.pose.shape[0])), 0), jnp.float32),
    )  # fmt: skip
    mk, jt = jax.jit(jax.vmap(lambda q: (BODY.markers(q), BODY.joints(q))))(params)  # one compilation
    return np.asarray(mk), np.asarray(jt)


def write(path: Path, markers: np.ndarray, *, z_up: bool, gaps=(), labels=None) -> Path:
    """Writes `markers` (30 fps, Y up, m) as a 60 fps C3D in mm, Z up if `z_up`, `Subj:` labels; `gaps` (frames, marker) unseen."""
    mk = np.stack([markers[:-1], (markers[1:] + markers[:-1]) / 2], 1).reshape(-1, *markers.shape[1:])
    if z_up:
        mk = np.stack([mk[..., 0], -mk[..., 2], mk[..., 1]], -1)  # a rotation about x
    res = np.ones(mk.shape[:2], np.float32)
    for frames, m in gaps:
        res[frames, m] = -1
    pts = np.where(res[..., None] > 0, mk * 1000, 0).astype(np.float32)
    path.write_bytes(c3d_file(pts, res, labels or [f"Subj:{n}" for n in BODY.marker_names], proc=84, scale=-1.0, rate=60.0))
    return path


@pytest.mark.parametrize("z_up", [True, False], ids=["z_up", "y_up"])
def test_c3d_window_is_the_training_canonical_window(tmp_path, walk, z_up):
    mk, jt = walk
    path = write(tmp_path / "walk.c3d", mk, z_up=z_up, gaps=[(slice(40, 43), 3)])  # a 3-frame gap: filled
    w = marker_window(read_motion(path), lay(), frame=60)
    assert w.end == 30 and w.x.shape == (T_HIS, 3 * BODY.num_markers)
    # The frames training builds from the body's joints (protocol §5 (docs/pages/protocol.md#marker-canonicalisation)), at the model's 30 fps.
    ref = canonicalise(mk[w.end + 1 - T_HIS : w.end + 1 + T_PRED], jt[w.end + 1 - T_HIS : w.end + 1 + T_PRED], BODY.names)
    np.testing.assert_allclose(w.x, ref[:T_HIS].reshape(T_HIS, -1), atol=1e-4)
    np.testing.assert_allclose(w.gt, ref[T_HIS:].reshape(T_PRED, -1), atol=1e-4)
    notes = " ".join(w.notes)
    assert "units: mm" in notes and "3 marker samples" in notes and "from 60 to 30 fps" in notes
    assert f"up axis: +{'z' if z_up else 'y'}" in notes
    # Back to the input's world: R^T q + o gives the observed markers (metres).
    back = w.x.reshape(T_HIS, -1, 3) @ w.canon[:3] + w.canon[3]
    np.testing.assert_allclose(back, w.observed, atol=1e-5)


def test_marker_mismatch_and_long_gaps_are_named(tmp_path, walk):
    mk, _ = walk
    labels = [f"Subj:{n}" for n in BODY.marker_names]
    labels[BODY.marker_names.index("LFHD")] = "Subj:XHEAD"
    with pytest.raises(DataError, match=r"missing \['LFHD'\]; extra \['XHEAD'\]"):
        marker_window(read_motion(write(tmp_path / "labels.c3d", mk, z_up=True, labels=labels)), lay())
    c7 = BODY.marker_names.index("C7")
    path = write(tmp_path / "gap.c3d", mk, z_up=True, gaps=[(slice(120, 140), c7)])  # 20 frames at 60 fps: not filled
    with pytest.raises(DataError, match=r"gap\.c3d: unseen markers in the observed window, input frames 120-130.*C7 \(frames 120-130\)"):
        marker_window(read_motion(path), lay(), frame=130)
    w = marker_window(read_motion(path), lay())  # without --frame: the latest window before the gap (model frames 60-70)
    assert 50 < w.end < 60 and any("without unfilled gaps" in s for s in w.notes)
    path = write(tmp_path / "never.c3d", mk, z_up=True, gaps=[(slice(0, 158), c7)])
    with pytest.raises(DataError, match=r"no window of the clip is free of them.*C7"):
        marker_window(read_motion(path), lay())


def test_fill_gaps_interpolates_only_short_interior_gaps():
    p = np.arange(20, dtype=float)[:, None, None].repeat(2, 1).repeat(3, 2)
    p[3:5, 0] = np.nan  # 2 frames: filled exactly (the motion is linear)
    p[8:12, 0] = np.nan  # 4 frames: longer than max_gap = 3
    p[:2, 1] = np.nan  # at the start: no seen frame before it
    out, n = fill_gaps(p, 3)
    assert n == 2 and np.array_equal(out[3:5, 0], np.arange(3.0, 5.0)[:, None].repeat(3, 1))
    assert np.isnan(out[8:12, 0]).all() and np.isnan(out[:2, 1]).all() and np.isfinite(out[12:]).all()


@pytest.mark.skipif(not C3D_DIR.is_dir(), reason=f"{C3D_DIR} absent (../shared/data not mounted)")
def test_vicon_marker_set_is_not_mojos():
    """The shared Vicon files carry 53 Vicon labels; the Bandai marker models MOJO's CMU-41: a clear mismatch."""
    with pytest.raises(DataError, match=r"squat\.c3d: markers do not match the model's: missing \['RBAK', 'LSHO'.*extra \['ARIEL'"):
        marker_window(read_motion(C3D_DIR / "squat.c3d"), {"joints": ["origin", *MARKER_SETS["bandai"]], "fps": 30.0, "t_his": 15, "t_pred": 60})
