"""Units of a folder of BVH files: each file's metres per unit, guessed or given, checked against a person's size.

    scales = file_scales({path: read_bvh(path) for path in files}, scale=None, root=folder)

Each file gets its own unit: the one given for it (`scale`: one number for every file, or
`{glob pattern: number}` matched against a file's path relative to the folder, its name or its
stem; `jaxmotion run --scale`), else `formats.bvh.guess_scale`'s guess. The guess is checked on the
motion: the body's size (the largest distance between two of its joints, median over a few frames)
must be a person's, `PLAUSIBLE_SIZE` metres, and the bodies of a folder must agree within a factor
`MAX_SIZE_RATIO`. Otherwise one `DataError` lists every file with its size, the unit used and the
units that would make it a person, and says how to pass them; a body is never silently 0.25 m tall.
"""

from __future__ import annotations

import fnmatch
from pathlib import Path

import numpy as np

from jaxmotion.data.plausible import body_size as positions_size
from jaxmotion.errors import DataError
from jaxmotion.formats.bvh import CMU_SCALE, Bvh, forward_kinematics, guess_scale, is_ground_skeleton

# A BVH body's size when its unit is guessed: narrower below than the readers' `plausible.PLAUSIBLE_SIZE`, because
# a body under 0.6 m across (an adult read in inches comes out 0.57 m) is read in the wrong unit far more often
# than it is an infant's.
PLAUSIBLE_SIZE = (0.6, 2.6)
MAX_SIZE_RATIO = 2.0
# Units a file may be in, offered in the error when its guess fails.
KNOWN_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254, "CMU/ASF unit": CMU_SCALE, "foot": 0.3048}


def body_size(bvh: Bvh, frames: int = 8) -> float:
    """Returns the body's size in file units: the largest distance between two joints, median over `frames` evenly spaced frames."""
    pick = np.unique(np.linspace(0, max(bvh.num_frames - 1, 0), frames).round().astype(int))
    with np.errstate(over="ignore", invalid="ignore"):
        p = forward_kinematics(bvh, pick)
    if is_ground_skeleton(bvh):
        p = p[:, 1:]  # a ground node's place says nothing about the body
    return positions_size(p, frames=len(p))


def given_scale(scale: float | dict[str, float] | None, rel: Path) -> float | None:
    """Returns the scale given for the file at `rel` (relative to the folder): the number, or the first matching pattern's."""
    if scale is None or isinstance(scale, (int, float)):
        return None if scale is None else float(scale)
    for pattern, s in scale.items():
        if any(fnmatch.fnmatch(name, pattern) for name in (str(rel), rel.name, rel.stem)):
            return float(s)
    return None


def parse_scale(values: list[str] | None) -> float | dict[str, float] | None:
    """Returns `--scale`'s value: one number for every file, or `{pattern: number}` from `PATTERN=NUMBER` entries."""
    if not values:
        return None
    if len(values) == 1 and "=" not in values[0]:
        return _number(values[0])
    out = {}
    for v in values:
        pattern, sep, number = v.rpartition("=")
        if not sep or not pattern:
            raise ValueError(f"--scale: give one number, or PATTERN=NUMBER entries (e.g. 'walk_*=0.01'), got {v!r}")
        out[pattern] = _number(number)
    return out


def _number(v: str) -> float:
    try:
        s = float(v)
    except ValueError:
        raise ValueError(f"--scale: {v!r} is not a number of metres per file unit") from None
    if not (s > 0 and np.isfinite(s)):
        raise ValueError(f"--scale: metres per file unit must be a positive number, got {v!r}")
    return s


def file_scales(bvhs: dict[Path, Bvh], scale: float | dict[str, float] | None, root: Path, *, one_file: bool = False) -> dict[Path, float]:
    """Returns metres per unit of every file (module docstring), or raises one `DataError` listing every file.

    `one_file`: `bvhs` is one clip given on its own (`jaxmotion predict`): the error names the file and
    its one `--scale NUMBER`.
    """
    rows, scales = [], {}
    for path, bvh in bvhs.items():
        if bvh.num_frames == 0:
            raise DataError(path, "'Frames: 0': a skeleton without motion, nothing to read")
        rel = path.relative_to(root) if path.is_relative_to(root) else Path(path.name)
        s = given_scale(scale, rel)
        how = "given"
        if s is None:
            how = "guessed"
            try:
                s = guess_scale(bvh)
            except DataError:
                s = None
        size = body_size(bvh)
        scales[path] = s
        rows.append((rel, size, s, how))
    sizes = [size * s for _, size, s, _ in rows if s is not None]
    lo, hi = PLAUSIBLE_SIZE
    bad = [r for r in rows if r[2] is None or not lo <= r[1] * r[2] <= hi]
    spread = max(sizes) / min(sizes) if sizes and min(sizes) > 0 else 1.0
    if one_file and bad:
        path, (rel, size, s, how) = next(iter(bvhs)), rows[0]
        raise DataError(path, f"units: no unit makes its body a person's ({lo:g}-{hi:g} m across): {_row(Path(path.name), size, s, how)}. "
                              "Fix: --scale NUMBER (metres per file unit)")
    if bad or spread > MAX_SIZE_RATIO:
        why = (f"{len(bad)} of {len(rows)} files have no unit that makes their body a person's ({lo:g}-{hi:g} m)" if bad
               else f"the bodies differ in size by a factor {spread:.1f} (more than {MAX_SIZE_RATIO:g})")
        lines = [_row(*r) for r in rows]
        raise DataError(
            root, f"units: {why}. Body size (largest joint distance) per file:\n  " + "\n  ".join(lines)
            + "\nFix: pass every file's metres per unit, --scale NUMBER for all files or --scale 'PATTERN=NUMBER' ... "
            "per file (glob on the path, name or stem; data_options {'scale': NUMBER or {PATTERN: NUMBER}} in a config, "
            "scale= to load_bvh_folder)"
        )
    return scales


def _row(rel: Path, size: float, s: float | None, how: str) -> str:
    if s is None:
        head = f"{rel}: {size:.4g} file units, no unit guessed"
    else:
        ok = PLAUSIBLE_SIZE[0] <= size * s <= PLAUSIBLE_SIZE[1]
        head = f"{rel}: {size:.4g} file units x {s:g} m ({how}) = {size * s:.2f} m{'' if ok else ' (not a person)'}"
    fits = [f"{name} ({u:g}: {size * u:.2f} m)" for name, u in KNOWN_UNITS.items()
            if PLAUSIBLE_SIZE[0] <= size * u <= PLAUSIBLE_SIZE[1] and u != s]
    return head + (f"; would fit: {', '.join(fits)}" if fits and (s is None or not ok) else "")
