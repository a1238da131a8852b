"""The package root holds the layers' folders and a few modules; the old module paths still resolve."""

import importlib
import warnings
from pathlib import Path

import pytest

import jaxmotion

ROOT_MODULES = {"__init__", "cli", "config", "dct", "diversity", "errors", "experiment", "gumbel", "losses", "method"}


def test_the_root_holds_only_the_layers_folders_and_its_own_modules():
    root = Path(jaxmotion.__file__).parent
    assert {p.stem for p in root.glob("*.py")} == ROOT_MODULES
    for folder in ("formats", "data", "body", "nn", "models", "methods", "train", "eval", "pictures", "tools"):
        assert (root / folder / "__init__.py").is_file(), folder


@pytest.mark.parametrize("old", sorted(jaxmotion._MOVED))
def test_a_moved_module_resolves_at_its_old_path_with_a_warning(old):
    with pytest.warns(DeprecationWarning, match=f"jaxmotion.{old} is now jaxmotion.{jaxmotion._MOVED[old]}"):
        module = getattr(jaxmotion, old)
    assert module is importlib.import_module(f"jaxmotion.{jaxmotion._MOVED[old]}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        exec(f"from jaxmotion import {old} as m", {})  # the import form of the old docs
    with pytest.raises(AttributeError, match="no attribute 'not_a_module'"):
        jaxmotion.not_a_module  # noqa: B018
