"""A C3D writer for tests: Intel, DEC or MIPS processor types, float or int16 point storage (c3d.org layout)."""

from __future__ import annotations

import struct

import numpy as np


def _encode_float(values, proc: int) -> bytes:
    a = np.asarray(values, np.float32).ravel()
    if proc == 85:  # DEC (VAX F): 4 x the IEEE value, 16-bit halves swapped
        raw = (a * 4).view(np.uint32)
        return (((raw & 0xFFFF) << 16) | (raw >> 16)).astype("<u4").tobytes()
    return a.astype(">f4" if proc == 86 else "<f4").tobytes()


def c3d_file(points: np.ndarray, residual: np.ndarray, labels: list[str], *, proc: int, scale: float, rate: float = 60.0,
             units: bytes = b"mm", pad: bytes = b" ") -> bytes:
    """Returns a C3D file of `points (F, M, 3)` mm for processor `proc` (84 Intel, 85 DEC, 86 MIPS); int16 when `scale > 0`.

    `units` is POINT:UNITS as stored (BTK's files: `b"mm\\x00\\x00"`); `pad` pads the labels to one width.
    """
    e = ">" if proc == 86 else "<"
    f, m = points.shape[:2]
    w = max(len(s) for s in labels)

    def param(name: str, t: int, dims: tuple[int, ...], data: bytes, last: bool = False) -> bytes:
        body = struct.pack(e + "bB", t, len(dims)) + bytes(dims) + data + b"\x00"
        return struct.pack(e + "bb", len(name), 1) + name.encode() + struct.pack(e + "h", 0 if last else 2 + len(body)) + body

    section = b"\x01\x50\x02" + bytes([proc]) + struct.pack(e + "bb", 5, -1) + b"POINT" + struct.pack(e + "h", 3) + b"\x00"
    section += param("USED", 2, (), struct.pack(e + "h", m)) + param("FRAMES", 2, (), struct.pack(e + "h", f))
    section += param("SCALE", 4, (), _encode_float([-abs(scale) if scale < 0 else scale], proc))
    section += param("RATE", 4, (), _encode_float([rate], proc)) + param("DATA_START", 2, (), struct.pack(e + "h", 4))
    section += param("UNITS", -1, (len(units),), units)
    section += param("LABELS", -1, (w, m), b"".join(s.encode().ljust(w, pad) for s in labels), last=True)
    hdr = bytearray(512)
    hdr[0], hdr[1] = 2, 0x50
    struct.pack_into(e + "hhhhh", hdr, 2, m, 0, 1, f, 0)
    hdr[12:16] = _encode_float([scale], proc)
    struct.pack_into(e + "h", hdr, 16, 4)
    hdr[20:24] = _encode_float([rate], proc)
    words = np.concatenate([points, residual[..., None]], axis=-1)
    if scale < 0:
        data = _encode_float(words, proc)
    else:
        data = np.round(words / np.array([scale, scale, scale, 1.0])).astype(e + "i2").tobytes()
    return bytes(hdr) + section.ljust(1024, b"\x00") + data
