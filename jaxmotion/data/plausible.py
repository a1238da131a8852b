"""The check every reader applies to the positions it returns: real floats, finite, a person's size.

    positions = check_positions(path, raw, "positions_3d['S9']['Walking']")   # float32, or a DataError

A file can be well formed and still not hold a person in metres: complex or boolean numbers that
numpy would cast without complaint, values past float32, a unit off by a thousand. Every reader (BVH
folders through `data.units`, the Human3.6M / HumanEva-I npz, AMASS, C3D and the npz clips of
`predict`) passes its positions through here once units are applied, so each of those is one
`DataError` naming the file, never a silently wrong result. The size of a body is the largest distance
between two of its points, median over a few frames, and must lie in `PLAUSIBLE_SIZE` metres.
"""

from __future__ import annotations

import os

import numpy as np

from jaxmotion.data.types import check_finite
from jaxmotion.errors import DataError

# The largest joint-to-joint distance of a person (an infant to an adult with raised hands; the lower bound as `guess_scale`'s).
PLAUSIBLE_SIZE = (0.5, 2.6)


def body_size(positions: np.ndarray, frames: int = 8) -> float:
    """Returns the largest distance between two points of `positions` (F, J, 3), median over `frames` evenly
    spaced frames; NaN points (marker gaps) are left out, NaN when no frame has two points."""
    if len(positions) == 0:
        return float("nan")
    pick = np.unique(np.linspace(0, len(positions) - 1, frames).round().astype(int))
    sizes = []
    for f in pick:  # one frame at a time: (J, J) distances
        q = np.asarray(positions[f], np.float64)
        q = q[~np.isnan(q).any(axis=-1)]
        if len(q) >= 2:
            with np.errstate(over="ignore", invalid="ignore"):
                sizes.append(np.linalg.norm(q[:, None] - q[None], axis=-1).max())
    return float(np.median(sizes)) if sizes else float("nan")


def check_positions(path: str | os.PathLike, positions, what: str = "positions", *, units: str = "",
                    gaps: bool = False) -> np.ndarray:
    """Returns `positions` (F, J, 3), in metres, as float32 after the shared checks (module docstring), or raises
    `DataError` naming `path` and `what`.

    `units` says how the file's numbers became metres, for the message when the size is wrong. `gaps`:
    NaN marks a missing point (C3D markers) and is kept; inf is still refused.
    """
    if not isinstance(positions, np.ndarray) or positions.ndim != 3 or positions.shape[-1] != 3:
        shape = positions.shape if isinstance(positions, np.ndarray) else type(positions).__name__
        raise DataError(path, f"{what} must be an (F, J, 3) array, got {shape}")
    if not np.issubdtype(positions.dtype, np.floating):
        raise DataError(path, f"{what} must hold real floating-point numbers (metres), got dtype {positions.dtype}")
    with np.errstate(over="ignore"):  # float64 beyond 3.4e38 becomes inf here, so check after the cast
        out = positions.astype(np.float32)
    check_finite(path, np.where(np.isnan(out), 0.0, out) if gaps else out, what)
    size = body_size(out)
    lo, hi = PLAUSIBLE_SIZE
    if np.isfinite(size) and not lo <= size <= hi:
        how = f" ({units})" if units else ""
        raise DataError(path, f"{what}: a body {size:.3g} m across (largest distance between two points, median over frames){how}, "
                              f"not a person's {lo:g}-{hi:g} m; wrong units?")
    return out
