"""C3D motion capture files (Vicon and others): labelled 3-D marker trajectories, with their gaps.

    rec = read_c3d("squat.c3d")
    rec.points        # (F, M, 3) float32 metres, NaN where a marker was not seen
    rec.mask          # (F, M) bool, True where seen
    rec.labels        # ("ARIEL", "LFHD", ...) without the "Subject:" prefix

A small reader of the public C3D format (c3d.org, "The C3D File Format User Guide"), with no
dependency: a 512-byte header, a parameter section of groups and typed parameters (POINT:LABELS,
LABELS2..., POINT:UNITS, POINT:RATE, POINT:SCALE, POINT:DATA_START, POINT:FRAMES), then per frame 4
words per point (x, y, z and a residual word, negative for an invalid point) and the analog samples,
as float32 when POINT:SCALE < 0, else int16 times the scale. Intel, DEC and MIPS processor types.
Trials past 65,535 frames: POINT:LONG_FRAMES, else TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD
(two 16-bit words each) when POINT:FRAMES is saturated, else POINT:FRAMES stored as a float.
Only points are read; analog channels are skipped.

Checked against ezc3d 1.7.2 (`tests/test_c3d_ezc3d.py`): same labels, rate, units, gaps and points
(max difference 1.4e-7 m, float32 rounding) on the Vicon files of `../shared/data/vicon-c3d`, on
files ezc3d writes (300 points through POINT:LABELS2, analog channels) and on integer and DEC
files. It is kept over ezc3d because ezc3d reads a truncated file as a shorter trial without an
error, accepts a negative rate or a NaN scale, crashes the Python process (SIGSEGV) on a parameter
with huge dimensions and no data, refuses POINT:FRAMES stored as a float and MIPS files, and reads
only 65,535 frames of a longer trial even with the TRIAL fields; this reader raises `DataError`
or reads them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from jaxmotion.errors import DataError

_UNIT_TO_METRES = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "dm": 0.1}


@dataclasses.dataclass
class C3D:
    """Marker trajectories of one C3D file, in metres; `raw_labels` keep the `Subject:` prefix."""

    labels: tuple[str, ...]
    points: np.ndarray  # (F, M, 3) float32, NaN at gaps
    mask: np.ndarray  # (F, M) bool
    rate: float
    units: str
    raw_labels: tuple[str, ...]
    path: str = ""

    @property
    def num_frames(self) -> int:
        return self.points.shape[0]

    def select(self, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Returns `(points (F, len(names), 3), mask)` in the order of `names`; absent names are gaps."""
        index = {n: i for i, n in enumerate(self.labels)}
        f = self.num_frames
        pts = np.full((f, len(names), 3), np.nan, np.float32)
        msk = np.zeros((f, len(names)), bool)
        for k, n in enumerate(names):
            if n in index:
                pts[:, k], msk[:, k] = self.points[:, index[n]], self.mask[:, index[n]]
        return pts, msk


def _text(raw: bytes) -> str:
    """Returns a C3D string without its padding: spaces, or NULs as C writers (BTK's test files) leave them."""
    return raw.decode("latin-1").strip(" \x00\t\r\n")


def _dec_to_ieee(raw: np.ndarray) -> np.ndarray:
    """Returns IEEE float32 from DEC (VAX F) floats read as little-endian uint32."""
    swapped = ((raw & 0xFFFF) << 16) | (raw >> 16)
    return swapped.astype(np.uint32).view(np.float32) / 4.0


class _Params(dict):
    """`{"GROUP:NAME": value}` of the parameter section (strings for char arrays)."""


def _parse_parameters(path: Path, buf: bytes, start: int, endian: str, dec: bool) -> _Params:
    def i8(o):
        return np.frombuffer(buf, np.int8, 1, o)[0].item()

    def i16(o):
        return np.frombuffer(buf, endian + "i2", 1, o)[0].item()

    if start + 4 > len(buf):
        raise DataError(path, "parameter section starts past the end of the file (truncated?)")
    groups: dict[int, str] = {}
    items = []
    o = start + 4
    while o + 2 <= len(buf):
        n, gid = i8(o), i8(o + 1)
        if n == 0 or gid == 0:
            break
        n = abs(n)
        name = _text(buf[o + 2 : o + 2 + n]).upper()
        p = o + 2 + n
        if p + 2 > len(buf):
            raise DataError(path, f"parameter {name!r} runs past the end of the file (truncated?)")
        nxt = i16(p)
        if gid < 0:
            groups[-gid] = name
        else:
            if p + 4 > len(buf) or p + 4 + buf[p + 3] > len(buf):
                raise DataError(path, f"parameter {name!r} runs past the end of the file (truncated?)")
            t, nd = i8(p + 2), buf[p + 3]
            dims = tuple(buf[p + 4 : p + 4 + nd])
            d = p + 4 + nd
            size = abs(t) * math.prod(dims)
            if t not in (-1, 1, 2, 4) or d + size > len(buf):
                raise DataError(path, f"parameter {name!r} has a bad type {t} or runs past the end of the file")
            data = buf[d : d + size]
            if t == -1:
                if len(dims) <= 1:
                    value = _text(data)
                else:
                    w = max(dims[0], 1)
                    value = [_text(data[i : i + w]) for i in range(0, len(data), w)]
            elif t == 1:
                value = np.frombuffer(data, np.int8).copy()
            elif t == 2:
                value = np.frombuffer(data, endian + "i2").copy()
            else:
                raw = np.frombuffer(data, endian + "u4").copy()
                value = _dec_to_ieee(raw) if dec else raw.view(endian + "f4")
            items.append((gid, name, value))
        if nxt == 0:
            break
        if p + nxt <= o:  # a pointer backwards would loop forever
            raise DataError(path, f"parameter {name!r} points back to offset {p + nxt} (corrupt parameter section)")
        o = p + nxt
    params = _Params()
    for gid, name, value in items:
        params[f"{groups.get(gid, str(gid))}:{name}"] = value
    return params


def _number(path: Path, params: _Params, key: str, default) -> float:
    """Returns the first value of numeric parameter `key` (`default` when absent or empty), finite or a DataError."""
    v = params.get(key, default)
    if isinstance(v, np.ndarray):
        v = v.reshape(-1)[0].item() if v.size else default
    if isinstance(v, (str, list)):
        raise DataError(path, f"parameter {key} must be a number, got the text {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise DataError(path, f"parameter {key} is {v}")
    return v


def _frame_count(path: Path, params: _Params, hdr: np.ndarray) -> int:
    """Returns the trial's frame count: POINT:LONG_FRAMES, TRIAL fields past 65,535, POINT:FRAMES, the header."""
    if "POINT:LONG_FRAMES" in params:
        return int(_number(path, params, "POINT:LONG_FRAMES", 0))
    frames = (int(hdr[4]) & 0xFFFF) - (int(hdr[3]) & 0xFFFF) + 1
    if "POINT:FRAMES" in params:  # the header's 16-bit frame numbers overflow on long trials
        pf = int(_number(path, params, "POINT:FRAMES", 0))
        frames = pf if pf >= 0 else pf + 65536
    start, end = params.get("TRIAL:ACTUAL_START_FIELD"), params.get("TRIAL:ACTUAL_END_FIELD")
    if frames == 65535 and all(isinstance(v, np.ndarray) and v.dtype == np.int16 and v.size == 2 for v in (start, end)):
        # Each field is a 32-bit frame number in two unsigned 16-bit words, low word first (Vicon).
        first, last = (int(v[0].item() & 0xFFFF) | int(v[1].item() & 0xFFFF) << 16 for v in (start, end))
        if last - first + 1 > 65535:
            frames = last - first + 1
    return frames


def read_c3d(path: str | os.PathLike) -> C3D:
    """Returns the labelled points of the C3D file at `path`, in metres, gaps as NaN and `mask` False.

    Raises FileNotFoundError if it does not exist and `jaxmotion.errors.DataError` (a ValueError)
    naming the file when it is not a C3D file or is truncated or inconsistent (labels vs point count,
    data past the end, a NaN or zero scale, a rate that is not positive). Non-finite coordinates are
    gaps, as are points whose residual word is negative.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: C3D file not found")
    buf = path.read_bytes()
    if len(buf) < 512 or buf[1] != 0x50:
        raise DataError(path, "not a C3D file (no 0x50 key in the header's second byte)")
    pblock = buf[0]
    pstart = (pblock - 1) * 512
    if pblock < 1 or pstart + 4 > len(buf):
        raise DataError(path, f"C3D header points to parameter block {pblock} past the end of the file")
    proc = buf[pstart + 3]
    if proc not in (84, 85, 86):
        raise DataError(path, f"unknown C3D processor type {proc} (expected 84 Intel, 85 DEC, 86 MIPS)")
    endian, dec = (">" if proc == 86 else "<"), proc == 85
    hdr = np.frombuffer(buf, endian + "i2", 256, 0)
    params = _parse_parameters(path, buf, pstart, endian, dec)

    num_points = int(_number(path, params, "POINT:USED", hdr[1]))
    if num_points < 0:
        num_points += 65536
    analog_words = int(hdr[2])
    if analog_words < 0:
        raise DataError(path, f"header says {analog_words} analog words per frame")
    frames = _frame_count(path, params, hdr)
    scale = _number(path, params, "POINT:SCALE", np.frombuffer(buf, endian + "f4", 1, 12)[0])
    if scale == 0:
        raise DataError(path, "POINT:SCALE is 0 (every point would be at the origin)")
    rate = _number(path, params, "POINT:RATE", np.frombuffer(buf, endian + "f4", 1, 20)[0])
    if rate <= 0:
        raise DataError(path, f"POINT:RATE must be positive, got {rate}")
    dstart = int(_number(path, params, "POINT:DATA_START", hdr[8]))
    if dstart < 0:
        dstart += 65536
    units = params.get("POINT:UNITS", "mm")
    if isinstance(units, list):  # a 2-D char array (ezc3d writes ["mm"]; an empty one when never set)
        units = next((u for u in units if u), "")
    units = (units.strip().lower() or "mm") if isinstance(units, str) else repr(units)
    if units not in _UNIT_TO_METRES:
        raise DataError(path, f"unknown POINT:UNITS {units!r} (known: {sorted(_UNIT_TO_METRES)})")

    labels: list[str] = []
    for key in ["POINT:LABELS"] + [f"POINT:LABELS{i}" for i in range(2, 100)]:
        if key not in params:
            break
        v = params[key]
        labels += v if isinstance(v, list) else [v]
    if not all(isinstance(label, str) for label in labels):
        raise DataError(path, "POINT:LABELS must be text")
    if len(labels) < num_points:
        raise DataError(path, f"{num_points} points but only {len(labels)} POINT:LABELS")
    labels = labels[:num_points]

    word = 4 if scale < 0 else 2
    frame_bytes = word * (4 * num_points + analog_words)
    d0 = (dstart - 1) * 512
    need = d0 + frame_bytes * frames
    if frames < 0 or d0 < 0 or need > len(buf):
        raise DataError(
            path, f"data of {frames} frames x {num_points} points needs {need} bytes, the file has {len(buf)} (truncated?)"
        )
    block = np.frombuffer(buf, np.uint8, frame_bytes * frames, d0).reshape(frames, frame_bytes)
    pts = block[:, : word * 4 * num_points].copy().reshape(-1)
    if word == 4:
        raw = pts.view(endian + "u4")
        vals = _dec_to_ieee(raw) if dec else raw.view(endian + "f4").astype(np.float32)
        vals = vals.reshape(frames, num_points, 4)
        xyz, res = vals[..., :3], vals[..., 3]
    else:
        vals = pts.view(endian + "i2").reshape(frames, num_points, 4).astype(np.float32)
        xyz, res = vals[..., :3] * abs(scale), vals[..., 3]
    mask = (res >= 0) & np.all(np.isfinite(xyz), axis=-1)
    points = np.where(mask[..., None], xyz * _UNIT_TO_METRES[units], np.nan).astype(np.float32)
    clean = tuple(label.split(":")[-1].strip() for label in labels)
    return C3D(clean, points, mask, rate, units, tuple(labels), str(path))
