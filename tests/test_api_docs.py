"""The API reference: one page per package of `jaxmotion/`, every module on its package's page (or named
internal below), every public symbol documented, every public array function with its shapes.

A public symbol is a function or class of a shown module, or a method of such a class, whose name does
not start with `_` (the filters of docs/mkdocs.yml); it needs a docstring, since mkdocstrings drops a
symbol without one. An array function (a parameter or the return annotated `Array`, `ndarray` or
`ArrayLike`, a random key aside) states its shapes: each array annotation is a jaxtyping one with its axes
(`Float[Array, "n k t d"]`), or the docstring writes a shape (`(n, t, d)`, `(K,)`, "shape").
"""

from __future__ import annotations

import pkgutil
import re
import textwrap
from pathlib import Path

import griffe
import pytest

import jaxmotion

ROOT = Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "pages" / "api"
# Modules that only serve the library itself, hidden from the reference (their docstrings stay for readers of
# the code).
INTERNAL = {
    "jaxmotion.formats.atomic": "whole-or-nothing file writes behind every file the library writes",
    "jaxmotion.train.run_lock": "the run folder's lock, taken by the runner",
    "jaxmotion.train.hugepages": "glibc huge-page settings, applied by the command line",
    "jaxmotion.train.compile_time": "compile-time counting for the evaluation records and the benchmarks",
}
KEYS = {"key", "rng"}  # a jax.random key is an array whose shape nobody needs told
SKIPPED_NAMES = {"setup"}  # Flax calls a module's `setup`; docs/mkdocs.yml filters it out too
ARRAY = re.compile(r"\b(Array|ndarray|ArrayLike)\b")
JAXTYPED = re.compile(r"\b\w+\[[\w.]+, *(['\"])[^'\"]*\1\]")  # Float[Array, "n k t d"]
DOC_SHAPE = re.compile(r"\(\s*[^()\n]*,[^()\n]*\)|\(\s*\w+\s*,?\s*\)|\bshapes?\b")


def page_of(module: str) -> str:
    """Returns the API page of a module: its package's, `jaxmotion.md` for the root package's own modules."""
    parts = module.split(".")
    return f"{parts[1]}.md" if len(parts) > 2 or (len(parts) == 2 and (ROOT / "jaxmotion" / parts[1]).is_dir()) else "jaxmotion.md"


def listed_modules() -> dict[str, list[str]]:
    """Returns {module: the API pages that list it}."""
    out: dict[str, list[str]] = {}
    for page in sorted(API.glob("*.md")):
        for m in re.findall(r"^::: (\S+)$", page.read_text(), re.M):
            out.setdefault(m, []).append(page.name)
    return out


def _modules(mod: griffe.Module):
    yield mod
    for sub in mod.modules.values():
        yield from _modules(sub)


def problems(package: str, search_path: Path, hidden: set[str] = frozenset()) -> tuple[list[str], list[str]]:
    """Returns `(undocumented, without shapes)`: the paths of the package's public symbols that lack a docstring,
    and of its public array functions that state no shapes."""
    pkg = griffe.load(package, search_paths=[str(search_path)], docstring_parser="google")
    undocumented, shapeless = [], []
    for mod in _modules(pkg):
        if mod.path in hidden:
            continue
        for name, obj in mod.members.items():
            if name.startswith("_") or obj.is_alias or not (obj.is_function or obj.is_class):
                continue
            objs = [obj]
            if obj.is_class:
                objs += [m for n, m in obj.members.items()
                         if not n.startswith("_") and n not in SKIPPED_NAMES and not m.is_alias and m.is_function]
            for o in objs:
                if not o.docstring or not o.docstring.value.strip():
                    undocumented.append(o.path)
                    continue
                if o.is_function:
                    anns = [str(p.annotation) for p in o.parameters if p.annotation is not None and p.name not in KEYS]
                    anns += [str(o.returns)] if o.returns is not None else []
                    bare = [a for a in anns if ARRAY.search(JAXTYPED.sub("", a))]
                    if bare and not DOC_SHAPE.search(o.docstring.value):
                        shapeless.append(o.path)
    return undocumented, shapeless


def test_every_module_is_on_its_package_page_once_or_named_internal():
    listed = listed_modules()
    modules = {"jaxmotion", *(m.name for m in pkgutil.walk_packages(jaxmotion.__path__, "jaxmotion."))}
    assert sorted(modules - set(listed) - set(INTERNAL)) == [], "modules missing from docs/pages/api/"
    assert sorted(set(listed) - modules) == [], "docs/pages/api/ names modules that do not exist"
    assert sorted(set(listed) & set(INTERNAL)) == [], "internal modules shown in docs/pages/api/"
    assert {m: p for m, p in listed.items() if p != [page_of(m)]} == {}, "a module not (only) on its package's page"
    nav = (ROOT / "docs" / "mkdocs.yml").read_text()
    assert sorted(p.name for p in API.glob("*.md") if f"api/{p.name}" not in nav) == [], "an API page not in the nav"


def test_every_public_symbol_has_a_docstring_and_every_array_function_its_shapes():
    undocumented, shapeless = problems("jaxmotion", ROOT, set(INTERNAL))
    assert undocumented == [], "public symbols without a docstring (mkdocstrings would drop them)"
    assert shapeless == [], "public array functions whose annotations and docstring state no shapes"


def test_the_check_finds_a_missing_docstring_and_missing_shapes(tmp_path):
    pkg = tmp_path / "fakepkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('"""A package."""\n')
    (pkg / "mod.py").write_text(textwrap.dedent('''
        """A module."""
        import jax
        from jaxtyping import Array, Float

        def shaped(x: Float[Array, "n t d"]) -> Float[Array, " n"]:
            """Returns the mean of each window."""

        def in_docstring(x: jax.Array) -> jax.Array:
            """Returns `x` of shape `(n, d)` doubled."""

        def bare(x: jax.Array) -> jax.Array:
            """Returns `x` doubled."""

        def undocumented(x: int) -> int:
            return x

        def _private(x: jax.Array) -> jax.Array:
            return x

        class Model:
            """A model."""

            def setup(self):
                pass

            def apply_it(self, x: jax.Array) -> jax.Array:
                return x
        '''))
    undocumented, shapeless = problems("fakepkg", tmp_path)
    assert undocumented == ["fakepkg.mod.undocumented", "fakepkg.mod.Model.apply_it"]
    assert shapeless == ["fakepkg.mod.bare"]


@pytest.mark.parametrize("module, page", [("jaxmotion", "jaxmotion.md"), ("jaxmotion.dct", "jaxmotion.md"),
                                          ("jaxmotion.eval", "eval.md"), ("jaxmotion.eval.metrics", "eval.md")])
def test_page_of(module, page):
    assert page_of(module) == page


def test_docstrings_cite_the_protocol_page_by_its_numbered_anchors():
    """No text of the repository cites a section of a file outside it; a docstring's `[protocol §N][anchor]` names
    a numbered heading of docs/pages/protocol.md, with its number."""
    headings = dict(re.findall(r"^## (\d+)\. .* \{#([a-z-]+)\}$", (ROOT / "docs" / "pages" / "protocol.md").read_text(), re.M))
    anchors = {a: n for n, a in headings.items()}
    assert len(anchors) >= 6, "docs/pages/protocol.md: its sections are numbered with explicit anchors"
    outside, wrong = [], []
    for path in sorted([*ROOT.glob("jaxmotion/**/*.py"), *ROOT.glob("tests/*.py"), *ROOT.glob("experiments/**/*.py"),
                        *ROOT.glob("benchmarks/**/*.py")]):
        text = path.read_text()
        rel = path.relative_to(ROOT)
        outside += [f"{rel}: {m}" for m in re.findall(r"PROTOCOL(?:\.md)? secs?\.? ?\d|PROTOCOL\.md", text)]
        for num, anchor in re.findall(r"\[protocol §(\d+)\]\[([^\]]+)\]", text):
            if anchors.get(anchor) != num:
                wrong.append(f"{rel}: [protocol §{num}][{anchor}]")
    assert outside == [], "citations of a file outside the repository: link the protocol page's section instead"
    assert wrong == [], f"links to a protocol section that does not exist or has another number; sections: {headings}"
