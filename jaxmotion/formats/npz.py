"""Reading a user's `.npz` without running code from it: plain arrays, and VideoPose3D's pickled dict of arrays.

    arrays = read_arrays("SMPLX_NEUTRAL.npz", keys=("v_template", "shapedirs"), what="body model")
    data = read_array_dict("data_3d_h36m.npz", "positions_3d")   # {subject: {action: array}}

Every npz a user hands to jaxmotion (datasets, AMASS sequences, body models, clips to predict from) is
read here. numpy told to unpickle would call whatever a pickle names (a downloaded file's
payload), so `read_arrays` reads numeric and string arrays only and refuses an object array by its
key; `read_array_dict` reads the one layout that is a pickle by design (VideoPose3D's
`positions_3d`) with an unpickler that builds only numpy arrays, dicts, lists, strings and numbers.
Every failure is a `DataError` naming the file and the key; none of numpy's messages about
`allow_pickle` reach the user.
"""

from __future__ import annotations

import io
import os
import pickle
import pickletools
import zipfile
from pathlib import Path

import numpy as np

from jaxmotion.errors import DataError

__all__ = ["read_arrays", "read_array_dict"]


def _members(path: Path, what: str) -> dict[str, str]:
    """Returns `{key: member name}` of the npz at `path`, or raises naming what the file is not."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: {what} not found")
    if not zipfile.is_zipfile(path):
        raise DataError(path, f"not an npz file (no zip archive: truncated, or another format?); a {what} is an npz")
    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
    except Exception as e:  # a corrupt central directory
        raise DataError(path, f"cannot read npz file ({type(e).__name__}: {e})") from e
    return {n.removesuffix(".npy"): n for n in names}


def _header(fp) -> tuple[tuple[int, ...], np.dtype]:
    version = np.lib.format.read_magic(fp)
    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _, dtype = read(fp)
    return shape, dtype


def read_arrays(path: str | os.PathLike, keys: tuple[str, ...] | None = None, *, what: str = "npz file",
                required: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Returns `{key: array}` of the npz at `path` (only `keys` when given, those present), never unpickling.

    An object array among the keys read is a `DataError` naming it: a data file holds plain arrays, and
    reading a pickled one would run whatever it names. `required` keys missing are a `DataError` listing them.
    """
    path = Path(path)
    members = _members(path, what)
    missing = [k for k in required if k not in members]
    if missing:
        raise DataError(path, f"missing keys {missing} (a {what} has {list(required)}; this file has {sorted(members)})")
    wanted = [k for k in (members if keys is None else keys) if k in members]
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for k in wanted:
                with zf.open(members[k]) as f:
                    fp = io.BytesIO(f.read())
                shape, dtype = _header(fp)
                if dtype.hasobject:
                    raise DataError(path, f"key {k!r} holds pickled Python objects, refused without running them (a {what} "
                                          "holds plain numeric or string arrays)")
                size = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if size > len(fp.getbuffer()) - fp.tell():  # checked before numpy allocates what the header claims
                    raise DataError(path, f"key {k!r}: the header says {shape} {dtype}, more than the file holds (truncated?)")
                fp.seek(0)
                out[k] = np.lib.format.read_array(fp, allow_pickle=False)
    except DataError:
        raise
    except Exception as e:  # zip, npy header and EOF errors from a corrupt or truncated file
        raise DataError(path, f"cannot read npz file ({type(e).__name__}: {e})") from e
    return out


def read_array_dict(path: str | os.PathLike, key: str) -> dict:
    """Returns the pickled `{name: {name: array}}` dict stored under `key` (VideoPose3D's `positions_3d`), or raises `DataError`.

    Read by hand rather than by `np.load`: `np.load` unpickles a file that is not a zip archive, and
    a pickle whose length field is corrupt allocates that length (up to 4 GB) before it finds the data
    missing. Here the pickle is first walked with `pickletools`, which checks every length against the
    bytes there are, then loaded by `_ArrayUnpickler`, which builds only arrays, dicts, lists, strings
    and numbers: a pickle naming any other callable (a downloaded file's payload) is refused before it
    is called.
    """
    path = Path(path)
    members = _members(path, "npz file")
    if key not in members:
        raise DataError(path, f"no key {key!r} (keys: {sorted(members)})")
    layout = f"{key!r} must be a pickled dict {{subject: {{action: array}}}}"
    try:
        with zipfile.ZipFile(path) as zf:
            fp = io.BytesIO(zf.read(members[key]))
        shape, dtype = _header(fp)
        if not (dtype.hasobject and shape == ()):
            raise DataError(path, f"{layout}, got a {dtype} array {shape}")
        start = fp.tell()
        for _ in pickletools.genops(fp):  # raises on a length past the end, before anything is allocated
            pass
        fp.seek(start)
        obj = _ArrayUnpickler(fp, path, key).load()
    except DataError:
        raise
    except Exception as e:  # zip, npy header, pickle and EOF errors from a corrupt or truncated file
        raise DataError(path, f"cannot read npz file ({type(e).__name__}: {e})") from e
    data = obj.item() if isinstance(obj, np.ndarray) and obj.dtype == object and obj.shape == () else obj
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise DataError(path, layout)
    return data


# What numpy's pickle of an object array of dicts of arrays names (numpy 1.x and 2.x module paths).
_PICKLE_GLOBALS = frozenset(
    [("numpy", "ndarray"), ("numpy", "dtype")]
    + [(m, f) for m in ("numpy.core.multiarray", "numpy._core.multiarray") for f in ("_reconstruct", "scalar")]
)


class _ArrayUnpickler(pickle.Unpickler):
    """`pickle.Unpickler` that resolves only numpy's array constructors (`_PICKLE_GLOBALS`).

    Dicts, lists, tuples, strings and numbers are pickle opcodes and need no lookup; every other
    object a pickle builds goes through `find_class` first, so a refused name is never imported or called.
    """

    def __init__(self, fp, path: Path, key: str):
        super().__init__(fp)
        self.path, self.key = path, key

    def find_class(self, module: str, name: str):
        if (module, name) not in _PICKLE_GLOBALS:
            raise DataError(self.path, f"{self.key!r} names {module}.{name}, which a dict of arrays never does; "
                                       "refused without running it (only numpy arrays, dicts, lists, strings and numbers are loaded)")
        return super().find_class(module, name)

    def persistent_load(self, pid):
        raise DataError(self.path, f"{self.key!r} holds a persistent reference, which a dict of arrays never does")
