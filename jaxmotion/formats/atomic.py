"""Whole-or-nothing file writes for caches and manifests that several processes may share.

Each write goes to a private temporary name in the target's folder (hidden, with the process id) and
is renamed over the target, which POSIX makes atomic: a reader sees the old file or the new one, never
half of one, and a process killed mid-write leaves only a stray temporary file, not a broken cache.
Two processes computing the same cache at once both succeed; the last rename wins.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def _tmp(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Writes `data` to `path` whole or not at all (parents created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp(path)
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Writes `text` (UTF-8) to `path` whole or not at all; returns the path."""
    return write_bytes_atomic(path, text.encode())


def savez_atomic(path: str | os.PathLike, **arrays) -> Path:
    """`np.savez(path, **arrays)` whole or not at all (no `.npz` appended: `path` is the file's name)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp(path)
    try:
        with open(tmp, "wb") as f:  # a file object: np.savez would append ".npz" to a name
            np.savez(f, **arrays)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
