"""Transparent huge pages for XLA:CPU's large buffers: when to ask glibc for them, and the restart that does.

XLA:CPU allocates every large temporary and output buffer of a jitted call afresh (glibc `malloc`,
which serves large requests, above a threshold of at most 32 MB, by a fresh `mmap`), and the kernel
then maps it in one 4 KiB page fault at a time while the first kernel writes it. For the library's
large arrays this costs more than the arithmetic: a 32 MB elementwise op ran 4x slower than memory allows (8,193 page faults a call),
MotionMap's heatmap step took 146,000 page faults, and more time in them than in its products
(benchmarks/results/memory.md). Where the kernel's transparent-huge-page mode is `madvise`
(Debian's and Ubuntu's default), glibc >= 2.35 advises huge pages for its own mappings when started
with `GLIBC_TUNABLES=glibc.malloc.hugetlb=1`: 2 MiB pages, 512 times fewer faults. glibc reads its
tunables once, at process start, so the `jaxmotion` command restarts itself once with the tunable
(`exec_with_hugepages`); code that imports jaxmotion into its own process sets the variable itself:

    GLIBC_TUNABLES=glibc.malloc.hugetlb=1 python my_train.py

`JAXMOTION_HUGEPAGES=0` turns the restart off. Where the mode is `always` (huge pages everywhere
already), `never`, or the C library is not glibc >= 2.35, nothing changes.
"""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

TUNABLE = "glibc.malloc.hugetlb=1"
THP_MODE = Path("/sys/kernel/mm/transparent_hugepage/enabled")
OFF_SWITCH = "JAXMOTION_HUGEPAGES"


def thp_mode(path: Path = THP_MODE) -> str | None:
    """Returns the kernel's transparent-huge-page mode (`always`, `madvise` or `never`), or None where it has none."""
    try:
        text = path.read_text()
    except OSError:
        return None
    chosen = [w[1:-1] for w in text.split() if w.startswith("[") and w.endswith("]")]
    return chosen[0] if chosen else None


def _glibc_at_least(major: int, minor: int) -> bool:
    lib, version = platform.libc_ver()
    if lib != "glibc" or not version:
        return False
    parts = version.split(".")
    try:
        return (int(parts[0]), int(parts[1])) >= (major, minor)
    except (IndexError, ValueError):
        return False


def wanted(environ: dict | None = None, mode: str | None = None) -> bool:
    """Returns whether this process would gain from a restart with the tunable (see the module docstring)."""
    environ = os.environ if environ is None else environ
    mode = thp_mode() if mode is None else mode
    if environ.get(OFF_SWITCH, "1") == "0" or has_tunable(environ):
        return False
    return sys.platform.startswith("linux") and mode == "madvise" and _glibc_at_least(2, 35)


def _others(environ) -> list[str]:
    return [t for t in environ.get("GLIBC_TUNABLES", "").split(":") if t and t != TUNABLE]


def has_tunable(environ) -> bool:
    """Returns whether `environ`'s `GLIBC_TUNABLES` holds `glibc.malloc.hugetlb=1`."""
    return TUNABLE in environ.get("GLIBC_TUNABLES", "").split(":")


def with_tunable(environ, on: bool = True) -> dict:
    """Returns a copy of `environ` whose `GLIBC_TUNABLES` holds `glibc.malloc.hugetlb=1` (`on`) or not, other tunables kept."""
    env = dict(environ)
    rest = _others(env) + ([TUNABLE] if on else [])
    env.pop("GLIBC_TUNABLES", None)
    if rest:
        env["GLIBC_TUNABLES"] = ":".join(rest)
    return env


def exec_with_hugepages() -> None:
    """Restarts this process with the same command line and the tunable set, where `wanted()`; else returns.

    Call it first thing in a program's entry point: the process is replaced (same PID, arguments,
    open files), so nothing done before it survives.
    """
    if not wanted() or not sys.executable:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, list(sys.orig_argv), with_tunable(os.environ))
