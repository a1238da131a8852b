"""The built-in methods, and the lookup that registers them: every module here that defines `METHOD` is one.

A method file reads like the method's training section: its stages (what is trained, on which
loss, for how long, with what frozen) and its predictors (how K futures are drawn). The maths
lives in its model file under `jaxmotion/models/`. Adding a file here that defines `METHOD` is
all it takes to add a built-in method; methods of other packages come in through `register` or
the `jaxmotion.methods` entry-point group.
"""

from __future__ import annotations

import importlib
import pkgutil
from importlib.metadata import entry_points

from jaxmotion.method import Method, register, registered

_LOADED = False


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for info in pkgutil.iter_modules(__path__):
        mod = importlib.import_module(f"{__name__}.{info.name}")
        if isinstance(getattr(mod, "METHOD", None), Method):
            register(mod.METHOD)
    for ep in entry_points(group="jaxmotion.methods"):
        m = ep.load()
        if not isinstance(m, Method):
            raise TypeError(f"entry point {ep.name!r} ({ep.value}) loads {type(m).__name__}, not a jaxmotion.method.Method")
        register(m)


def get_method(name: str) -> Method:
    """Returns the registered method `name` (built-in, from an entry point, or `register`ed by you)."""
    _load()
    found = registered()
    if name not in found:
        raise ValueError(f"unknown method {name!r}; registered: {sorted(found)}")
    return found[name]


def methods() -> dict[str, Method]:
    """Returns every registered method by name."""
    _load()
    return registered()
