"""The train/test split of a plain folder of BVH clips (one that no dataset protocol describes).

Default (`folder_split`): by subject where the file names carry one (the stem before its first `_`,
CMU's `SS_TT` naming, as `load_bvh_folder` names subjects): the last `ceil(test_fraction x subjects)`
subjects in sorted order are test; with a single subject (or names without `_`), the last
`ceil(test_fraction x files)` files in sorted order are test. Either way at least one file is
train and one is test. `test_files` (glob patterns matched against a file's path relative to
the folder, its name and its stem; `jaxmotion run --test-files`) chooses the test files instead.
"""

from __future__ import annotations

import fnmatch
import math
from collections.abc import Sequence
from pathlib import Path

from jaxmotion.errors import DataError

TEST_FRACTION = 0.2


def folder_split(
    root: str | Path, test_files: Sequence[str] | None = None, test_fraction: float = TEST_FRACTION
) -> tuple[dict[Path, str], str]:
    """Returns `({file: "train" | "test"}, a sentence saying how)` for every `*.bvh` under `root` (module docstring)."""
    root = Path(root)
    files = sorted(root.rglob("*.bvh"))
    if not files:
        raise DataError(root, "no .bvh files")
    rel = [f.relative_to(root) for f in files]
    if test_files:
        test = set()
        for pat in test_files:
            hit = {f for f, r in zip(files, rel) if any(fnmatch.fnmatch(s, pat) for s in (str(r), r.name, r.stem))}
            if not hit:
                raise DataError(root, f"--test-files pattern {pat!r} matches none of the {len(files)} files ({_names(rel)})")
            test |= hit
        if len(test) == len(files):
            raise DataError(root, f"--test-files selects all {len(files)} files; leave at least one for training")
        how = f"test files chosen by --test-files {list(test_files)}"
    else:
        if len(files) < 2:
            raise DataError(
                root, f"one .bvh file ({rel[0]}): a folder needs at least two, one to train on and one to test "
                "(or a dataset protocol)"
            )
        subjects = sorted({f.stem.split("_")[0] for f in files if "_" in f.stem})
        if len(subjects) >= 2 and all("_" in f.stem for f in files):
            held = set(subjects[-max(1, math.ceil(test_fraction * len(subjects))) :])
            test = {f for f in files if f.stem.split("_")[0] in held}
            how = f"by subject (file-name prefix before '_'): test subjects {sorted(held)} of {len(subjects)}"
        else:
            n = min(len(files) - 1, max(1, math.ceil(test_fraction * len(files))))
            test = set(files[-n:])
            how = f"by file: the last {n} of {len(files)} files (sorted by path) are test"
    split = {f: ("test" if f in test else "train") for f in files}
    names = lambda which: _names([r for f, r in zip(files, rel) if split[f] == which])  # noqa: E731
    return split, f"{how}; train: {names('train')}; test: {names('test')}"


def _names(rel: list[Path], n: int = 6) -> str:
    shown = ", ".join(str(r) for r in rel[:n])
    return shown + (f", ... ({len(rel)} in all)" if len(rel) > n else "")
