"""The package's layers import one way: `formats <- body <- data`, models below evaluation and training, no cycles, no private names.

Every module under `jaxmotion/` is parsed with `ast` (nothing is imported), and every import is
read, function-level ones included. A module belongs to a unit: its subpackage (`formats`, `body`,
`data`, `nn`, `models`, `train`) or, for a top-level module, the module itself (`realism`, `cli`,
...). The tests check that

- the layers import downwards only: `formats` imports nothing from jaxmotion but `errors` (the
  error types, a leaf that imports nothing of jaxmotion), `body` may import `formats`, `data` may
  import `body` and `formats`, never the other way round;
- a model file (`jaxmotion/models/`) imports nothing above the models (`ABOVE_MODELS`: the metrics,
  evaluation, methods, training, the experiment driver, the command line), and another model only
  where its paper builds on it (`MODEL_ON_MODEL`);
- the unit graph and the module graph, each from every import (function-level ones included: an
  import inside a function hides a cycle from the interpreter, not from the reader), have no cycle;
- the layers do not import each other inside functions (what held the old cycle together);
- no unit imports another unit's private name (`from jaxmotion.data.datasets import _x`, or
  `datasets._x` on an imported module).

An import is an edge to the module it loads: `import p.q` and `from p import q` (q a module) to
`p.q`; `from p.q import x` (x a name, not a module) to `p.q`, a package's `__init__` when `p.q` is a
package. Python also runs the `__init__` of every package above a loaded module; that is not an
edge. A package `__init__` that imports its submodules (`jaxmotion.body`), whose submodules import
each other by full path, would otherwise read as a cycle through the `__init__`, and that order
always resolves (a submodule loads completely before the `__init__` reads its names). A name taken
from an `__init__` (`from jaxmotion.body import fit_markers`) is an edge to it, which is where a
cycle through an `__init__` can fail.

To check another checkout, point `JAXMOTION_LAYERS_ROOT` at its root (the folder holding
`jaxmotion/`) or at its package folder:

    JAXMOTION_LAYERS_ROOT=/tmp/jm-old python -m pytest -q tests/test_layers.py

`python tests/test_layers.py` prints the unit graph, any cycle and any private cross-unit use.
"""

from __future__ import annotations

import ast
import os
from pathlib import Path
from typing import NamedTuple

import pytest

# The layers from the bottom: each may import the layers before it, never those after it.
LAYERS = ("formats", "body", "data")
# Below every layer: the error types (`jaxmotion.errors`), which import nothing of jaxmotion.
LEAVES = ("errors",)
# What a model file may not import: everything above the models.
ABOVE_MODELS = ("jaxmotion.eval", "jaxmotion.experiment", "jaxmotion.method", "jaxmotion.methods", "jaxmotion.cli",
                "jaxmotion.train", "jaxmotion.tools")  # fmt: skip
# A model builds on another only where its paper does: DLow's and MOJO's CVAE is the shared GRU CVAE,
# MOJO's second stage is DLow's Q network per DCT band.
MODEL_ON_MODEL = frozenset({
    ("jaxmotion.models.dlow", "jaxmotion.models.cvae"),
    ("jaxmotion.models.mojo", "jaxmotion.models.cvae"),
    ("jaxmotion.models.mojo", "jaxmotion.models.dlow"),
    ("jaxmotion.models.divsamp", "jaxmotion.models.gsps"),  # DivSamp's release trains its CVAE with GSPS's angle loss
})  # fmt: skip


class Import(NamedTuple):
    importer: str  # dotted module name
    target: str  # dotted module name (a package for `from package import name`)
    name: str | None  # the name taken from `target`, or None when the module itself is imported
    lineno: int
    top_level: bool  # runs when the importer is imported (not inside a function, not TYPE_CHECKING)
    path: Path

    def where(self) -> str:
        what = f"from {self.target} import {self.name}" if self.name else f"import {self.target}"
        kind = "module level" if self.top_level else "in a function"
        return f"{self.path}:{self.lineno}: {what} ({kind})"


def package_dir() -> Path:
    root = Path(os.environ.get("JAXMOTION_LAYERS_ROOT", Path(__file__).resolve().parents[1]))
    return root / "jaxmotion" if (root / "jaxmotion").is_dir() else root


def find_modules(pkg: Path) -> dict[str, Path]:
    """Returns `{dotted name: file}` for every module of the package at `pkg`."""
    out = {}
    for f in sorted(pkg.rglob("*.py")):
        parts = (pkg.name,) + f.relative_to(pkg).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def unit(module: str) -> str:
    """Returns the subpackage (or top-level module) a module belongs to: `jaxmotion.data.types` -> `data`."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _dotted(node: ast.expr) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


class _Visitor(ast.NodeVisitor):
    def __init__(self, module: str, path: Path, modules: dict[str, Path]):
        self.module, self.path, self.modules = module, path, modules
        self.is_package = path.name == "__init__.py"
        self.root = module.split(".")[0]
        self.imports: list[Import] = []
        self.bindings: dict[str, str] = {}  # local name -> module it names
        self.attributes: list[tuple[str, int]] = []  # dotted attribute chains read
        self._depth = 0  # > 0 inside a function or a TYPE_CHECKING block

    def _function(self, node):
        self._depth += 1
        self.generic_visit(node)
        self._depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _function

    def visit_If(self, node: ast.If):
        if _is_type_checking(node.test):
            self._depth += 1
            for n in node.body:
                self.visit(n)
            self._depth -= 1
            for n in node.orelse:
                self.visit(n)
        else:
            self.generic_visit(node)

    def _add(self, target: str, name: str | None, node: ast.stmt):
        self.imports.append(Import(self.module, target, name, node.lineno, self._depth == 0, self.path))

    def visit_Import(self, node: ast.Import):
        for a in node.names:
            if a.name.split(".")[0] != self.root:
                continue
            self._add(a.name, None, node)
            if a.asname:
                self.bindings[a.asname] = a.name
            else:
                self.bindings[self.root] = self.root

    def visit_ImportFrom(self, node: ast.ImportFrom):
        if node.level:
            here = self.module.split(".")
            package = here if self.is_package else here[:-1]
            package = package[: len(package) - (node.level - 1)]
            base = ".".join(package + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        if base.split(".")[0] != self.root:
            return
        for a in node.names:
            sub = f"{base}.{a.name}"
            if sub in self.modules:  # `from jaxmotion.data import datasets`: a module
                self._add(sub, None, node)
                self.bindings[a.asname or a.name] = sub
            else:
                self._add(base, a.name, node)

    def visit_Attribute(self, node: ast.Attribute):
        d = _dotted(node)
        if d is not None:
            self.attributes.append((d, node.lineno))
        self.generic_visit(node)


def scan(pkg: Path):
    """Returns `(modules, imports, private)`: every import of a jaxmotion module, and cross-unit private uses."""
    modules = find_modules(pkg)
    imports, private = [], []
    for module, path in modules.items():
        v = _Visitor(module, path, modules)
        v.visit(ast.parse(path.read_text(), filename=str(path)))
        imports += v.imports
        for imp in v.imports:
            if unit(imp.target) == unit(module):
                continue
            names = imp.target.split(".")[1:] + ([imp.name] if imp.name else [])
            if any(_is_private(n) for n in names):
                private.append(imp.where())
        # `datasets._x` where `datasets` names a module of another unit.
        for chain, lineno in v.attributes:
            head, *rest = chain.split(".")
            if head not in v.bindings or not rest:
                continue
            full = v.bindings[head].split(".") + rest
            for i in range(len(full) - 1, 0, -1):  # the longest module prefix owns the next name
                owner, attr = ".".join(full[:i]), full[i]
                if owner in modules:
                    if _is_private(attr) and unit(owner) != unit(module):
                        private.append(f"{path}:{lineno}: {owner}.{attr} (attribute of an imported module)")
                    break
    return modules, imports, list(dict.fromkeys(private))


def find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """Returns one cycle `[a, b, ..., a]` of the directed graph, or None."""
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(edges.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m) :] + [m]
            if m not in state and (c := visit(m)):
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(edges):
        if n not in state and (c := visit(n)):
            return c
    return None


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Returns one cycle `[a, b, ..., a]` per strongly connected component of more than one node (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    components: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = {stack.pop()}
            while v not in comp:
                comp.add(stack.pop())
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return [find_cycle({a: edges.get(a, set()) & comp for a in comp}) for comp in components]


def module_edges(imports: list[Import]) -> tuple[dict[str, set[str]], dict[tuple[str, str], list[Import]]]:
    """Returns the module graph of every import (function-level ones included), and the imports behind each edge."""
    edges: dict[str, set[str]] = {}
    why: dict[tuple[str, str], list[Import]] = {}
    for imp in imports:
        if imp.importer != imp.target:
            edges.setdefault(imp.importer, set()).add(imp.target)
            why.setdefault((imp.importer, imp.target), []).append(imp)
    return edges, why


def model_imports_against_layers(imports: list[Import]) -> list[str]:
    """Returns each import of a model file that reaches above the models, or into a model its paper does not build on."""
    bad = []
    for imp in imports:
        a, b = imp.importer, imp.target
        if not a.startswith("jaxmotion.models.") or a == b:
            continue
        if any(b == p or b.startswith(p + ".") for p in ABOVE_MODELS):
            bad.append(f"{imp.where()}: {a} imports {b}, above the models")
        elif b.startswith("jaxmotion.models.") and (a, b) not in MODEL_ON_MODEL:
            bad.append(f"{imp.where()}: {a} imports {b}, another model (MODEL_ON_MODEL lists where a paper builds on one)")
    return bad


def _unit_edges(imports: list[Import]) -> tuple[dict[str, set[str]], dict[tuple[str, str], list[Import]]]:
    edges: dict[str, set[str]] = {}
    why: dict[tuple[str, str], list[Import]] = {}
    for imp in imports:
        a, b = unit(imp.importer), unit(imp.target)
        if a != b:
            edges.setdefault(a, set()).add(b)
            why.setdefault((a, b), []).append(imp)
    return edges, why


def _explain(cycle: list[str], why: dict[tuple[str, str], list[Import]]) -> str:
    lines = [" -> ".join(cycle)]
    for a, b in zip(cycle, cycle[1:]):
        lines += [f"  {a} -> {b}: {imp.where()}" for imp in why.get((a, b), [])[:3]]
    return "\n".join(lines)


@pytest.fixture(scope="module")
def scanned():
    pkg = package_dir()
    modules, imports, private = scan(pkg)
    assert len(modules) > 20, f"{pkg}: expected the jaxmotion package, found {len(modules)} modules"
    return modules, imports, private


def test_layers_import_downwards_only(scanned):
    _, imports, _ = scanned
    bad = []
    for imp in imports:
        a, b = unit(imp.importer), unit(imp.target)
        if a in LEAVES:
            bad.append(f"{a} -> {b}: {imp.where()}")
        if a == b or a not in LAYERS or b in LEAVES:
            continue
        if a == LAYERS[0]:  # the file formats need nothing but numpy
            bad.append(f"{a} -> {b}: {imp.where()}")
        elif b in LAYERS and LAYERS.index(b) > LAYERS.index(a):
            bad.append(f"{a} -> {b}: {imp.where()}")
    assert not bad, f"imports against the layer order {' <- '.join(LAYERS)}:\n" + "\n".join(bad)


def test_no_cycle_between_subpackages(scanned):
    _, imports, _ = scanned
    edges, why = _unit_edges(imports)  # module-level and function-level imports
    cycle = find_cycle(edges)
    assert cycle is None, "import cycle between jaxmotion's subpackages:\n" + _explain(cycle, why)


def test_no_cycle_between_modules(scanned):
    _, imports, _ = scanned
    edges, why = module_edges(imports)
    found = cycles(edges)
    assert not found, "import cycles between modules (function-level imports included):\n" + "\n".join(_explain(c, why) for c in found)


def test_models_import_only_downward(scanned):
    _, imports, _ = scanned
    bad = model_imports_against_layers(imports)
    assert not bad, "model files importing against the layers:\n" + "\n".join(bad)


def test_layers_import_each_other_only_at_module_level(scanned):
    _, imports, _ = scanned
    bad = [
        imp.where()
        for imp in imports
        if not imp.top_level and unit(imp.importer) in LAYERS and unit(imp.target) != unit(imp.importer)
    ]
    assert not bad, "function-level imports across the layers (import at module level):\n" + "\n".join(bad)


def test_no_private_name_imported_across_subpackages(scanned):
    _, _, private = scanned
    assert not private, "private names used across jaxmotion's subpackages:\n" + "\n".join(private)


# The checker itself, on a small package with every fault: it must see each one.


def _write(pkg: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        (pkg / name).parent.mkdir(parents=True, exist_ok=True)
        (pkg / name).write_text(text)


def test_checker_finds_cycles_and_private_imports(tmp_path):
    pkg = tmp_path / "jaxmotion"
    files = {
        "__init__.py": "",
        "formats/__init__.py": "",
        "formats/bvh.py": "import numpy as np\n",
        "body/__init__.py": "",
        "body/skeleton.py": "from jaxmotion.formats.bvh import np\n\ndef f():\n    from jaxmotion.data.datasets import _g\n",
        "data/__init__.py": "",
        "data/datasets.py": (
            "from ..body import skeleton\nimport jaxmotion.body.skeleton as sk\n\n"
            "def _g():\n    return sk._hidden, skeleton.f\n"
        ),
        "a.py": "from jaxmotion import b\n",
        "b.py": "from . import a\n",
    }
    _write(pkg, files)
    modules, imports, private = scan(pkg)
    assert "jaxmotion.formats" in modules and "jaxmotion.data.datasets" in modules
    edges, _ = _unit_edges(imports)
    assert edges["data"] == {"body"} and edges["body"] == {"formats", "data"}
    assert find_cycle(edges) == ["a", "b", "a"]
    del edges["a"]
    assert find_cycle(edges) == ["body", "data", "body"]
    assert private == [
        f"{pkg / 'body/skeleton.py'}:4: from jaxmotion.data.datasets import _g (in a function)",
        f"{pkg / 'data/datasets.py'}:5: jaxmotion.body.skeleton._hidden (attribute of an imported module)",
    ]
    top = {(i.importer, i.target) for i in imports if i.top_level}
    assert ("jaxmotion.body.skeleton", "jaxmotion.data.datasets") not in top
    assert {("jaxmotion.a", "jaxmotion.b"), ("jaxmotion.b", "jaxmotion.a")} <= top


def test_checker_finds_function_level_cycles_and_model_imports(tmp_path):
    pkg = tmp_path / "jaxmotion"
    files = {
        "__init__.py": "",
        "eval/__init__.py": "",
        "eval/metrics.py": "from jaxmotion.nn import layers\n",
        "nn/__init__.py": "from jaxmotion.nn.layers import Dense\n",  # an __init__ importing its submodule
        "nn/layers.py": "from jaxmotion.nn.init import rule\nDense = 1\n",
        "nn/init.py": "rule = 0\n",
        "train/__init__.py": "",
        "train/loop.py": "",
        "models/__init__.py": "",
        "models/cvae.py": "",
        "models/dlow.py": "from jaxmotion.models.cvae import x\n",
        "models/a.py": "from jaxmotion.nn import layers\n\n\ndef f():\n    from jaxmotion.eval import metrics\n",
        "models/b.py": "from . import a\nimport jaxmotion.train.loop\n",
        "data/__init__.py": "",
        "data/x.py": "import jaxmotion.data.y\n",
        "data/y.py": "def g():\n    from jaxmotion.data.x import h\n",
        "data/z.py": "from jaxmotion.data.x import h\n",
        "body/__init__.py": "from jaxmotion.body.fit import fit\n",
        "body/fit.py": "from jaxmotion.body.params import p\nfit = 1\n",
        "body/params.py": "p = 0\n",
    }
    _write(pkg, files)
    _, imports, _ = scan(pkg)
    edges, why = module_edges(imports)
    assert edges["jaxmotion.body.fit"] == {"jaxmotion.body.params"}  # no edge to the package's __init__
    assert edges["jaxmotion.models.a"] == {"jaxmotion.nn.layers", "jaxmotion.eval.metrics"}
    assert cycles(edges) == [["jaxmotion.data.x", "jaxmotion.data.y", "jaxmotion.data.x"]]  # the only cycle
    assert _explain(cycles(edges)[0], why).splitlines()[2].endswith("data/y.py:2: from jaxmotion.data.x import h (in a function)")
    assert model_imports_against_layers(imports) == [
        f"{pkg / 'models/a.py'}:5: import jaxmotion.eval.metrics (in a function): jaxmotion.models.a imports jaxmotion.eval.metrics, above the models",
        f"{pkg / 'models/b.py'}:1: import jaxmotion.models.a (module level): jaxmotion.models.b imports jaxmotion.models.a, "
        "another model (MODEL_ON_MODEL lists where a paper builds on one)",
        f"{pkg / 'models/b.py'}:2: import jaxmotion.train.loop (module level): jaxmotion.models.b imports jaxmotion.train.loop, above the models",
    ]
    (pkg / "body/params.py").write_text("from jaxmotion.body import fit\n")  # a name of the __init__ (here a module too)
    (pkg / "body/fit.py").write_text("from jaxmotion.body import helper\n")  # a name of the __init__: an edge to it
    _, imports, _ = scan(pkg)
    found = cycles(module_edges(imports)[0])
    assert ["jaxmotion.body", "jaxmotion.body.fit", "jaxmotion.body"] in found and len(found) == 2


def main() -> int:
    pkg = package_dir()
    modules, imports, private = scan(pkg)
    edges, why = _unit_edges(imports)
    top, _ = _unit_edges([i for i in imports if i.top_level])
    print(f"{pkg}: {len(modules)} modules, {len(imports)} imports of jaxmotion modules")
    for a in sorted(edges):
        deps = [b if b in top.get(a, ()) else f"{b} (in a function only)" for b in sorted(edges[a])]
        print(f"  {a} -> {', '.join(deps)}")
    cycle = find_cycle(edges)
    print("unit cycle:", _explain(cycle, why) if cycle else "none")
    mod_edges, mod_why = module_edges(imports)
    mod_cycles = cycles(mod_edges)
    print("module cycles:", "\n".join(_explain(c, mod_why) for c in mod_cycles) if mod_cycles else "none")
    bad = model_imports_against_layers(imports)
    print("model imports against the layers:", "\n  ".join([""] + bad) if bad else "none")
    print("private names across units:", "\n  ".join([""] + private) if private else "none")
    return 1 if cycle or mod_cycles or private or bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
