"""Fuzzed parsers: mutated BVH, C3D and npz files parse to finite data or raise `DataError`.

Valid files (fabricated here, plus the shared BVH and C3D files when `../shared/data` is present)
are mutated by truncation, byte flips, deleted and duplicated lines, wrong channel counts, absurd
frame counts, NaN/inf and huge values, wrong parameter types and wrong array dtypes and shapes.
Every case must end within `CASE_SECONDS`, allocate at most `64 x file size + 16 MB`, and either
parse to finite data (C3D: NaN exactly at the gaps) or raise `jaxmotion.errors.DataError` whose
`path` is the file. Files that once failed are kept in `tests/data/fuzz_regressions/`.

CI runs a fixed, derandomised budget of `JAXMOTION_FUZZ_EXAMPLES` (default 100) examples per test; a
longer, random fuzz prints the outcome counts per format (and writes them to
`JAXMOTION_FUZZ_REPORT` when set):

    JAXMOTION_FUZZ_EXAMPLES=3000 python -m pytest -q -s tests/test_fuzz_parsers.py
"""

from __future__ import annotations

import collections
import io
import json
import math
import os
import pickle
import shutil
import signal
import struct
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxmotion.data.datasets import load_bvh_folder, load_dataset
from jaxmotion.errors import DataError
from jaxmotion.formats.bvh import read_bvh
from jaxmotion.formats.c3d import read_c3d

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
REGRESSIONS = Path(__file__).resolve().parent / "data" / "fuzz_regressions"
EXAMPLES = int(os.environ.get("JAXMOTION_FUZZ_EXAMPLES", "100"))
LONG = "JAXMOTION_FUZZ_EXAMPLES" in os.environ
CASE_SECONDS = 5.0
FUZZ = settings(
    max_examples=EXAMPLES, deadline=None, derandomize=not LONG, database=None if not LONG else settings().database,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)
COUNTS: collections.Counter = collections.Counter()


@pytest.fixture(scope="module", autouse=True)
def report_counts(request):
    yield
    if not COUNTS:
        return
    summary = {f"{fmt} {what}": n for (fmt, what), n in sorted(COUNTS.items())}
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(f"fuzz cases ({EXAMPLES} examples per test): {json.dumps(summary)}")
    if os.environ.get("JAXMOTION_FUZZ_REPORT"):
        Path(os.environ["JAXMOTION_FUZZ_REPORT"]).write_text(json.dumps(summary, indent=1))


@pytest.fixture(scope="module")
def scratch():
    d = Path(tempfile.mkdtemp(prefix="jaxmotion-fuzz-"))
    yield d
    shutil.rmtree(d, ignore_errors=True)


class CaseTimeout(Exception):
    pass


def _alarm(signum, frame):
    raise CaseTimeout(f"a fuzz case ran past {CASE_SECONDS} s")


def outcome(fmt: str, path: Path, load, check, paths: tuple[Path, ...] = ()) -> str:
    """Returns "parsed" or "DataError" for `load(path)`; anything else (another error, a hang, a huge allocation) fails."""
    size = path.stat().st_size
    old = signal.signal(signal.SIGALRM, _alarm)
    tracemalloc.start()
    try:
        signal.setitimer(signal.ITIMER_REAL, CASE_SECONDS)
        try:
            result = load(path)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        what = "parsed"
    except DataError as e:
        assert e.path in {str(p) for p in (path, *paths)}, f"DataError names {e.path}, not the file {path}: {e}"
        assert str(e).startswith(e.path) and len(e.problem) > 5, str(e)
        what = "DataError"
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        signal.signal(signal.SIGALRM, old)
    assert peak <= 64 * size + 16 * 2**20, f"{path}: parsing a {size}-byte file allocated {peak} bytes"
    if what == "parsed":
        check(result)
    COUNTS[fmt, what] += 1
    return what


def write_case(scratch: Path, name: str, data: bytes) -> Path:
    """Returns a fresh folder's `name` holding `data` (a folder per case: `load_bvh_folder` reads them all)."""
    folder = Path(tempfile.mkdtemp(dir=scratch))
    path = folder / name
    path.write_bytes(data)
    return path


# --- mutations -----------------------------------------------------------------------------------

SPECIAL_TOKENS = ["nan", "inf", "-inf", "1e308", "-1e308", "1e39", "abc", "0x10", "1e-320", "9" * 30, "", "1_0"]


def byte_op():
    return st.one_of(
        st.tuples(st.just("truncate"), st.floats(0, 1)),
        st.tuples(st.just("flip"), st.floats(0, 1), st.integers(1, 255)),
        st.tuples(st.just("flip_head"), st.integers(0, 4095), st.integers(1, 255)),
    )


def apply_byte_op(data: bytes, op) -> bytes:
    if not data:
        return data
    if op[0] == "truncate":
        return data[: int(op[1] * len(data))]
    i = min(int(op[1] * len(data)), len(data) - 1) if op[0] == "flip" else op[1] % len(data)
    return data[:i] + bytes([data[i] ^ op[2]]) + data[i + 1 :]


def line_op():
    idx = st.floats(0, 1)
    return st.one_of(
        st.tuples(st.just("delete_line"), idx),
        st.tuples(st.just("dup_line"), idx),
        st.tuples(st.just("token"), idx, idx, st.sampled_from(SPECIAL_TOKENS)),
        st.tuples(st.just("channels"), idx, st.sampled_from([-2, -1, 1, 5, 10**6])),
        st.tuples(st.just("drop_channel"), idx),
        st.tuples(st.just("frames"), st.sampled_from(["0", "-1", "1", "10", "1000000000", "1" + "0" * 30, "two", ""])),
        st.tuples(st.just("frame_time"), st.sampled_from(["0", "-0.01", "1e-320", "nan", "inf", "1e300", "x"])),
    )


def _pick(seq, f: float):
    return min(int(f * len(seq)), len(seq) - 1)


def apply_line_op(text: str, op) -> str:
    lines = text.split("\n")
    kind = op[0]
    if kind in ("delete_line", "dup_line"):
        i = _pick(lines, op[1])
        lines[i : i + 1] = [] if kind == "delete_line" else [lines[i], lines[i]]
    elif kind == "token":
        i = _pick(lines, op[1])
        tokens = lines[i].split()
        if tokens:
            tokens[_pick(tokens, op[2])] = op[3]
            lines[i] = " ".join(tokens)
    elif kind in ("channels", "drop_channel"):
        chans = [i for i, line in enumerate(lines) if line.strip().startswith("CHANNELS")]
        if chans:
            i = chans[_pick(chans, op[1])]
            tokens = lines[i].split()
            if kind == "channels":
                tokens[1] = str(int(tokens[1]) + op[2]) if tokens[1].lstrip("-").isdigit() else tokens[1]
            elif len(tokens) > 2:
                tokens.pop()
            lines[i] = " ".join(tokens)
    elif kind in ("frames", "frame_time"):
        key = "Frames:" if kind == "frames" else "Frame Time:"
        for i, line in enumerate(lines):
            if line.strip().startswith(key):
                lines[i] = f"{key} {op[1]}"
                break
    return "\n".join(lines)


# --- BVH -----------------------------------------------------------------------------------------

CHAIN = """\
HIERARCHY
ROOT A
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT B
  {
    OFFSET 0 50 0
    CHANNELS 3 Yrotation Xrotation Zrotation
    JOINT C
    {
      OFFSET 0 40 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      End Site
      {
        OFFSET 0 0 30
      }
    }
  }
  JOINT D
  {
    OFFSET 50 50 50
    CHANNELS 3 Xposition Yposition Zposition
  }
}
MOTION
Frames: 4
Frame Time: 0.04
10 20 30 0 0 0   0 0 0    0 0 0   0 1 0
1 2 3 90 0 0     90 90 0  45 10 20   0 0 1
1 2 4 80 0 0     90 80 0  45 10 20   0 0 2
1 2 5 70 0 0     90 70 0  45 10 20   0 0 3
"""

# CHAIN below a ground node (as Bandai's joint_Root) with 3 constant position channels.
_hier, _motion = CHAIN.split("MOTION\n")
GROUNDED = (
    "HIERARCHY\nROOT G\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
    + _hier.removeprefix("HIERARCHY\n").replace("ROOT A", "JOINT A")
    + "}\nMOTION\n"
    + "\n".join(line if not line[:1].isdigit() else "0 0 0 " + line for line in _motion.split("\n"))
)


def _bvh_head(path: Path, frames: int = 12) -> str:
    """Returns the HIERARCHY and the first `frames` motion rows of a real BVH file."""
    lines = path.read_text().splitlines()
    m = lines.index("MOTION")
    head = lines[: m + 1] + [f"Frames: {frames}", lines[m + 2]] + lines[m + 3 : m + 3 + frames]
    return "\n".join(head) + "\n"


def bvh_bases() -> list[tuple[str, str]]:
    bases = [("chain", CHAIN), ("grounded", GROUNDED)]
    cmu = SHARED_DATA / "cmu-bvh" / "01_01.bvh"
    if cmu.is_file():
        bases.append(("cmu_01_01_head", _bvh_head(cmu)))
    return bases


def load_folder(path: Path):
    return load_bvh_folder(path.parent)


def check_bvh_dataset(ds):
    for seq in ds.test:
        assert seq.positions.dtype == np.float32 and np.all(np.isfinite(seq.positions))
    assert ds.fps > 0 and math.isfinite(ds.fps)


def test_fabricated_bvh_bases_parse(scratch):
    for name, text in bvh_bases():
        path = write_case(scratch, f"{name}.bvh", text.encode())
        assert outcome("bvh", path, read_bvh, lambda b: None) == "parsed"
        assert outcome("bvh", path, load_folder, check_bvh_dataset, (path.parent,)) == "parsed"
    assert load_bvh_folder(write_case(scratch, "g.bvh", GROUNDED.encode()).parent).skeleton.names[0] == "A"


@FUZZ
@given(
    base=st.sampled_from(bvh_bases()),
    lines=st.lists(line_op(), max_size=3),
    raw=st.lists(byte_op(), max_size=2),
)
def test_mutated_bvh(scratch, base, lines, raw):
    name, text = base
    for op in lines:
        text = apply_line_op(text, op)
    data = text.encode()
    for op in raw:
        data = apply_byte_op(data, op)
    path = write_case(scratch, f"{name}.bvh", data)

    def check_bvh(bvh):
        assert np.all(np.isfinite(bvh.motion)) and np.all(np.isfinite(bvh.offsets))
        assert bvh.motion.shape[1] == sum(len(c) for c in bvh.channels) and bvh.fps > 0

    if outcome("bvh", path, read_bvh, check_bvh) == "parsed":
        outcome("bvh_folder", path, load_folder, check_bvh_dataset, (path.parent,))


# --- C3D -----------------------------------------------------------------------------------------


def _param(gid: int, name: str, t: int, dims: tuple[int, ...], data: bytes, last: bool = False) -> bytes:
    body = struct.pack("<bB", t, len(dims)) + bytes(dims) + data + b"\x00"  # type, dims, data, empty description
    nxt = 0 if last else 2 + len(body)
    return struct.pack("<bb", len(name), gid) + name.encode() + struct.pack("<h", nxt) + body


def _char(gid: int, name: str, text: str | list[str]) -> bytes:
    if isinstance(text, str):
        return _param(gid, name, -1, (len(text),), text.encode())
    w = max(len(s) for s in text)
    return _param(gid, name, -1, (w, len(text)), b"".join(s.ljust(w).encode() for s in text))


def c3d_bytes(points: np.ndarray, residual: np.ndarray, *, rate: float = 100.0, scale: float = -0.1,
              labels: list[str] | None = None, edits: dict | None = None) -> bytes:  # fmt: skip
    """Returns a C3D file (Intel; float data when `scale < 0`, else int16) of `points (F, M, 3)` in mm.

    `edits` replaces a POINT parameter's encoded bytes by name (`{"USED": _char(1, "USED", "x")}`)
    or drops it (None): the parameters a corrupt exporter gets wrong.
    """
    f, m = points.shape[:2]
    labels = labels if labels is not None else [f"S:M{i}" for i in range(m)]
    data_start = 4  # blocks 2-3 hold the parameters
    params = {
        "USED": _param(1, "USED", 2, (), struct.pack("<h", m)),
        "FRAMES": _param(1, "FRAMES", 2, (), struct.pack("<h", f)),
        "SCALE": _param(1, "SCALE", 4, (), struct.pack("<f", scale)),
        "RATE": _param(1, "RATE", 4, (), struct.pack("<f", rate)),
        "DATA_START": _param(1, "DATA_START", 2, (), struct.pack("<h", data_start)),
        "UNITS": _char(1, "UNITS", "mm"),
        "LABELS": _char(1, "LABELS", labels) if labels else _param(1, "LABELS", -1, (0, 0), b""),
    }
    for k, v in (edits or {}).items():
        if v is None:
            params.pop(k, None)
        else:
            params[k] = v
    group = struct.pack("<bb", 5, -1) + b"POINT" + struct.pack("<h", 3) + b"\x00"
    items = list(params.values())
    # The last parameter ends the section (next offset 0).
    last = items[-1]
    n = last[0]
    items[-1] = last[: 2 + n] + b"\x00\x00" + last[4 + n :]
    section = b"\x01\x50\x02\x54" + group + b"".join(items)
    section = section.ljust(1024, b"\x00")[:1024]
    hdr = bytearray(512)
    hdr[0], hdr[1] = 2, 0x50
    struct.pack_into("<hhhhhf", hdr, 2, m, 0, 1, f, 0, scale)  # points, analog, first and last frame, gap, scale
    struct.pack_into("<h", hdr, 16, data_start)
    struct.pack_into("<f", hdr, 20, rate)
    if scale < 0:
        words = np.concatenate([points, residual[..., None]], axis=-1).astype("<f4")
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            words = np.concatenate([points / abs(scale), residual[..., None]], axis=-1)
            words = np.clip(np.nan_to_num(words), -32768, 32767).astype("<i2")
    return bytes(hdr) + section + words.tobytes()


PARAM_EDITS = {
    "none": {},
    "used_text": {"USED": _char(1, "USED", "x")},
    "used_huge": {"USED": _param(1, "USED", 2, (), struct.pack("<h", 30000))},
    "used_float_nan": {"USED": _param(1, "USED", 4, (), struct.pack("<f", math.nan))},
    "frames_huge": {"FRAMES": _param(1, "FRAMES", 2, (), struct.pack("<h", 32767))},
    "frames_negative": {"FRAMES": _param(1, "FRAMES", 2, (), struct.pack("<h", -2))},
    "frames_text": {"FRAMES": _char(1, "FRAMES", "many")},
    "scale_nan": {"SCALE": _param(1, "SCALE", 4, (), struct.pack("<f", math.nan))},
    "scale_zero": {"SCALE": _param(1, "SCALE", 4, (), struct.pack("<f", 0.0))},
    "scale_inf": {"SCALE": _param(1, "SCALE", 4, (), struct.pack("<f", -math.inf))},
    "rate_negative": {"RATE": _param(1, "RATE", 4, (), struct.pack("<f", -5.0))},
    "rate_text": {"RATE": _char(1, "RATE", "fast")},
    "data_start_zero": {"DATA_START": _param(1, "DATA_START", 2, (), struct.pack("<h", 0))},
    "data_start_far": {"DATA_START": _param(1, "DATA_START", 2, (), struct.pack("<h", 30000))},
    "labels_int": {"LABELS": _param(1, "LABELS", 2, (2,), struct.pack("<hh", 1, 2))},
    "labels_zero_width": {"LABELS": _param(1, "LABELS", -1, (0, 3), b"")},
    "labels_missing": {"LABELS": None},
    "units_unknown": {"UNITS": _char(1, "UNITS", "furlong")},
    "units_int": {"UNITS": _param(1, "UNITS", 2, (), struct.pack("<h", 7))},
    "dims_huge": {"RATE": _param(1, "RATE", 4, (255, 255, 255), b"")},
    "bad_type": {"RATE": _param(1, "RATE", 3, (), b"\x00\x00\x00")},
}
VALUES = [0.0, 1.5, -1000.0, 250.0, math.nan, math.inf, -math.inf, 1e30, 3e38]


@st.composite
def c3d_case(draw) -> tuple[str, bytes]:
    f, m = draw(st.integers(0, 5)), draw(st.integers(1, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    points = rng.normal(0, 500, (f, m, 3)).astype(np.float32)
    for _ in range(draw(st.integers(0, 3))):
        if f:
            points[rng.integers(f), rng.integers(m), rng.integers(3)] = draw(st.sampled_from(VALUES))
    residual = np.where(rng.random((f, m)) < 0.2, -1.0, 0.5).astype(np.float32)
    scale = draw(st.sampled_from([-0.1, -1.0, 0.1]))
    edit = draw(st.sampled_from(["none"] * 10 + sorted(PARAM_EDITS)))
    data = c3d_bytes(points, residual, scale=scale, edits=PARAM_EDITS[edit])
    return f"fab_{edit}", data


def c3d_bases() -> list[tuple[str, bytes]]:
    out = []
    for name in ("squat.c3d", "nick_freeform_001.c3d"):
        if (SHARED_DATA / "vicon-c3d" / name).is_file():
            out.append((name.removesuffix(".c3d"), (SHARED_DATA / "vicon-c3d" / name).read_bytes()))
    return out


def header_op():
    return st.tuples(st.just("header"), st.sampled_from([0, 2, 4, 6, 8, 16]), st.sampled_from([0, -1, 1, 2, 255, 30000, -32768]))


def apply_header_op(data: bytes, op) -> bytes:
    if len(data) < 18:
        return data
    b = bytearray(data)
    if op[1] == 0:  # the parameter block number, one byte
        b[0] = op[2] & 0xFF
    else:
        struct.pack_into("<h", b, op[1], op[2])
    return bytes(b)


def check_c3d(rec):
    f, m = rec.mask.shape
    assert rec.points.shape == (f, m, 3) and len(rec.labels) == m
    assert np.all(np.isfinite(rec.points[rec.mask])) and np.all(np.isnan(rec.points[~rec.mask]))
    assert rec.rate > 0 and math.isfinite(rec.rate)


@FUZZ
@given(case=c3d_case(), ops=st.lists(st.one_of(byte_op(), header_op()), max_size=3))
def test_mutated_c3d(scratch, case, ops):
    name, data = case
    for op in ops:
        data = apply_header_op(data, op) if op[0] == "header" else apply_byte_op(data, op)
    outcome("c3d", write_case(scratch, f"{name}.c3d", data), read_c3d, check_c3d)


@pytest.mark.skipif(not c3d_bases(), reason=f"shared C3D files not found in {SHARED_DATA / 'vicon-c3d'}")
@FUZZ
@given(base=st.sampled_from(c3d_bases() or [("none", b"")]), ops=st.lists(st.one_of(byte_op(), header_op()), min_size=1, max_size=3))
def test_mutated_real_c3d(scratch, base, ops):
    name, data = base
    for op in ops:
        data = apply_header_op(data, op) if op[0] == "header" else apply_byte_op(data, op)
    outcome("c3d_real", write_case(scratch, f"{name}.c3d", data), read_c3d, check_c3d)


# --- npz (Human3.6M / HumanEva-I, VideoPose3D layout) ---------------------------------------------

H36M_SUBJECTS = ("S1", "S5", "S6", "S7", "S8", "S9", "S11")
HUMANEVA_SUBJECTS = ("Train/S1", "Train/S2", "Train/S3", "Validate/S1", "Validate/S2", "Validate/S3")


def npz_dict(layout: str, t: int) -> dict:
    subjects, joints = (H36M_SUBJECTS, 32) if layout == "h36m" else (HUMANEVA_SUBJECTS, 15)
    base = np.linspace(-1, 1, t * joints * 3, dtype=np.float32).reshape(t, joints, 3)
    return {s: {"Walking": base + i, "Eating": base - i} for i, s in enumerate(subjects)}


ARRAY_EDITS = {
    "nan": lambda a: _set(a, math.nan),
    "inf": lambda a: _set(a, -math.inf),
    "float64_overflow": lambda a: _set(a.astype(np.float64), 1e39),
    "complex": lambda a: a.astype(np.complex64),
    "text": lambda a: a.astype(str),
    "object": lambda a: a.astype(object),
    "bool": lambda a: a > 0,
    "int": lambda a: a.astype(np.int16),
    "drop_joint": lambda a: a[:, 1:],
    "two_dims": lambda a: a.reshape(a.shape[0], a.shape[1] * 3),
    "scalar": lambda a: np.float32(1.0),
    "list": lambda a: a.tolist(),
    "empty": lambda a: a[:0],
    "xy_only": lambda a: a[..., :2],
}


def _set(a: np.ndarray, v: float) -> np.ndarray:
    a = a.copy()
    if a.size:
        a[a.shape[0] // 2, a.shape[1] // 2, 1] = v
    return a


@st.composite
def npz_case(draw) -> tuple[str, bytes]:
    layout = draw(st.sampled_from(["h36m", "humaneva"]))
    data = npz_dict(layout, draw(st.integers(0, 4)))
    name = layout
    what = draw(st.sampled_from(["array", "array", "drop_subject", "int_keys", "mixed_keys", "not_dict", "other_key", "nothing"]))
    subjects = sorted(data)
    s = subjects[draw(st.integers(0, len(subjects) - 1))]
    if what == "array":
        edit = draw(st.sampled_from(sorted(ARRAY_EDITS)))
        data[s]["Walking"] = ARRAY_EDITS[edit](data[s]["Walking"])
        name += f"_{edit}"
    elif what == "drop_subject":
        del data[s]
    elif what == "int_keys":
        data[s] = {1: data[s]["Walking"]}
    elif what == "mixed_keys":
        data[s][7] = data[s]["Walking"]
    elif what == "not_dict":
        data[s] = data[s]["Walking"]
    name += f"_{what}" if what != "array" else ""
    buf = io.BytesIO()
    if what == "other_key":
        np.savez(buf, positions=np.zeros(3))
    else:
        np.savez(buf, positions_3d=np.array(data, dtype=object))
    return name, buf.getvalue()


def check_npz_dataset(ds):
    assert ds.train and ds.test
    for seq in ds.train + ds.test:
        assert seq.positions.dtype == np.float32 and np.all(np.isfinite(seq.positions))


@FUZZ
@given(case=npz_case(), ops=st.lists(byte_op(), max_size=2))
def test_mutated_npz(scratch, case, ops):
    name, data = case
    for op in ops:
        data = apply_byte_op(data, op)
    outcome("npz", write_case(scratch, f"{name}.npz", data), load_dataset, check_npz_dataset)


# --- regressions ---------------------------------------------------------------------------------

# Each file once crashed, hung or passed non-finite data through (README.md there); the error it must
# now give, or null where it must parse to finite data.
REGRESSION_ERRORS = json.loads((REGRESSIONS / "expected.json").read_text()) if (REGRESSIONS / "expected.json").is_file() else {}
LOADERS = {".bvh": lambda p: read_bvh(p) and load_folder(p), ".c3d": read_c3d, ".npz": load_dataset}


@pytest.mark.parametrize("name", sorted(REGRESSION_ERRORS))
def test_regression_corpus(scratch, name):
    path = write_case(scratch, name, (REGRESSIONS / name).read_bytes())
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, CASE_SECONDS)
    try:
        if REGRESSION_ERRORS[name] is None:
            ds = LOADERS[path.suffix](path)
            assert all(np.isfinite(seq.positions).all() for seq in ds.train + ds.test)
            return
        with pytest.raises(DataError, match=REGRESSION_ERRORS[name]) as e:
            LOADERS[path.suffix](path)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    assert e.value.path in (str(path), str(path.parent))


def test_regression_corpus_is_present():
    assert len(REGRESSION_ERRORS) >= 5 and all((REGRESSIONS / n).is_file() for n in REGRESSION_ERRORS)


def test_data_error_is_a_picklable_value_error():
    e = pickle.loads(pickle.dumps(DataError("/x/y.bvh", "bad row 3")))
    assert isinstance(e, ValueError) and (e.path, e.problem, str(e)) == ("/x/y.bvh", "bad row 3", "/x/y.bvh: bad row 3")
