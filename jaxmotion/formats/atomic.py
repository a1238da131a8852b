"""Whole-or-nothing file writes: every file the library writes (results, manifests, pictures, caches).

Each write goes to a private temporary name in the target's folder (hidden, with the process id) and
is renamed over the target, which POSIX makes atomic: a reader sees the old file or the new one, never
half of one, and a process killed mid-write leaves only a stray temporary file, not a broken cache.
Two processes computing the same cache at once both succeed; the last rename wins. A write that fails
(a full disk) leaves the previous file as it was.

    with atomic_path("samples.png") as tmp:    # any writer that takes a file name
        fig.savefig(tmp)
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np


def _tmp(path: Path) -> Path:
    # The target's suffix last: writers that pick the format from the name (matplotlib, np.savez) still see it.
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yields a temporary name beside `path` (parents created) for the caller to write; renamed onto `path`
    when the block ends without an exception, removed when it raises (the previous `path` kept)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        if e.filename is None and e.errno is not None:  # a failed write() names no file (a full disk): name the target
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Writes `data` to `path` whole or not at all (parents created); returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Writes `text` (UTF-8) to `path` whole or not at all; returns the path."""
    return write_bytes_atomic(path, text.encode())


def savez_atomic(path: str | os.PathLike, **arrays) -> Path:
    """`np.savez(path, **arrays)` whole or not at all (no `.npz` appended: `path` is the file's name)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:  # a file object: np.savez would append ".npz" to a name
        np.savez(f, **arrays)
    return Path(path)
