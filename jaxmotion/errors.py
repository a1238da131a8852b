"""The errors a user can cause, each naming what is wrong and where: a file, a config field, a checkpoint.

    try:
        ds = load_dataset("data_3d_h36m.npz")
    except DataError as e:
        print(e.path, e.problem)     # the file, and what is wrong with it (frame, row, key)

All five are `ValueError`s, so code that caught `ValueError` before still catches them. They are
raised at the boundary (parsers, loaders, config loading, checkpoint restore, run folders, command-line
options), before any jitted code. The `jaxmotion` command prints any of them as one line, exit code 2.
"""

from __future__ import annotations

import os


class DataError(ValueError):
    """A motion file (BVH, C3D, npz) that is malformed or holds NaN/inf: `path` and `problem`."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")

    def __reduce__(self):  # picklable (multiprocessing, pytest-xdist) with its two arguments
        return type(self), (self.path, self.problem)


class ConfigError(ValueError):
    """A config with unknown fields, wrong types or impossible values: `problems` lists every one."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, list(problems)
        if len(self.problems) == 1:  # one line, as every other error the command prints
            super().__init__(f"{source}: {self.problems[0]}")
            return
        lines = "".join(f"\n  - {p}" for p in self.problems)
        super().__init__(f"{source}: {len(self.problems)} problems in the config:{lines}")

    def __reduce__(self):
        return type(self), (self.source, self.problems)


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (unreadable, truncated, written for another stage), or cannot be written."""


class RunFolderError(ValueError):
    """A run folder that cannot be used now: held by another process, or not writable: `path` and `problem`."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")

    def __reduce__(self):
        return type(self), (self.path, self.problem)


class UsageError(ValueError):
    """A command-line option (or the function argument behind it) outside what it accepts; the message names it."""
