"""The documentation runs: every fenced Python block of README.md and docs/pages/ is executed, shell blocks
are run or marked as not run, and the generated tables are up to date (the API reference: tests/test_api_docs.py).

Conventions (docs/pages/about-docs.md): every fence names its language. The Python blocks of one page run
in order in one namespace, in a temporary folder holding the files the pages use (`my_clips/`: five
fabricated BVH clips of five subjects; `clip.bvh`: one more). A shell block (`bash`, `sh`, `shell`,
`console`) is preceded by `<!-- docs-test: run -->` (run here, with `jaxmotion` this checkout's CLI) or by
`<!-- not run: REASON -->`.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import os
import re
import subprocess
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import pytest

from humanoid_bvh import humanoid_bvh

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted((DOCS / "pages").glob("*.md"))]
SHELL = {"bash", "sh", "shell", "console"}
RUN_MARK = "<!-- docs-test: run -->"
NOT_RUN = re.compile(r"^<!-- not run: \S.* -->$")


@dataclass
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    mark: str  # the last non-blank line before the fence

    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """Returns the fenced code blocks of a markdown page (fences at any indentation, ``` or longer)."""
    out, lines = [], page.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)(`{3,})(.*)$", lines[i])
        if not m:
            i += 1
            continue
        indent, fence, info = m.groups()
        body, j = [], i + 1
        while j < len(lines) and not re.match(rf"^\s*{fence}\s*$", lines[j]):
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j])
            j += 1
        if j == len(lines):
            raise AssertionError(f"{page.relative_to(ROOT)}:{i + 1}: fence never closed")
        before = [ln.strip() for ln in lines[:i] if ln.strip()]
        out.append(Block(page, i + 1, info.strip().split(" ")[0].lower(), "\n".join(body) + "\n", before[-1] if before else ""))
        i = j + 1
    return out


ALL = [b for p in PAGES for b in blocks(p)]


def test_every_fence_names_its_language_and_every_shell_block_is_run_or_marked():
    assert [b.where() for b in ALL if not b.lang] == [], "a fence without a language: name it (python, bash, text, ...)"
    unmarked = [b.where() for b in ALL if b.lang in SHELL and b.mark != RUN_MARK and not NOT_RUN.match(b.mark)]
    assert unmarked == [], f"shell blocks neither run ({RUN_MARK}) nor marked '<!-- not run: REASON -->'"
    assert [b.where() for b in ALL if b.lang == "python" and b.mark.startswith("<!--")] == [], "every Python block runs"
    assert any(b.lang == "python" for b in ALL if b.page.name == "README.md")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("docs")
    (d / "my_clips").mkdir()
    for i in range(1, 6):
        humanoid_bvh("bandai", d / "my_clips" / f"s{i}_walk.bvh", frames=150, seed=i)
    humanoid_bvh("bandai", d / "clip.bvh", frames=150, seed=9)
    return d


@pytest.mark.parametrize("page", [p for p in PAGES if any(b.lang == "python" for b in blocks(p))], ids=lambda p: p.name)
def test_python_examples_run(page, workdir, monkeypatch):
    monkeypatch.chdir(workdir)
    module = types.ModuleType("docs_example")  # a real module: dataclasses and pickling look their class's module up
    monkeypatch.setitem(sys.modules, module.__name__, module)
    namespace = module.__dict__
    for b in (b for b in blocks(page) if b.lang == "python"):
        out = io.StringIO()
        try:
            with contextlib.redirect_stdout(out):
                exec(compile(b.code, b.where(), "exec"), namespace)
        except Exception as e:
            raise AssertionError(f"the example at {b.where()} failed: {type(e).__name__}: {e}\n{out.getvalue()}") from e


@pytest.mark.parametrize("block", [b for b in ALL if b.mark == RUN_MARK], ids=lambda b: b.where())
def test_marked_shell_examples_run(block, workdir):
    assert block.lang in SHELL
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    script = f'jaxmotion() {{ "{sys.executable}" -m jaxmotion.cli "$@"; }}\nset -e\n{block.code}'
    r = subprocess.run(["bash", "-c", script], cwd=workdir, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"{block.where()} failed:\n{r.stdout}\n{r.stderr}"


def test_experiments_readme_lists_every_script_and_only_existing_files():
    text = (ROOT / "experiments" / "README.md").read_text()
    listed = set(re.findall(r"^\| `([a-z_0-9]+\.py)` \|", text, re.M))
    scripts = {p.name for p in (ROOT / "experiments").glob("*.py")}
    configs = {p.name for p in (ROOT / "experiments" / "configs").glob("*.py")}
    assert sorted(scripts - listed) == [], "experiments/README.md does not list these scripts"
    assert sorted(listed - scripts - configs) == [], "experiments/README.md names files that do not exist"


def _generator():
    spec = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_generated_tables_are_up_to_date():
    """docs/generate.py renders the results and benchmark pages, their figures and the README's methods table from
    the committed result files; regenerating must change nothing (a figure's coordinates: up to their last digit)."""
    gen = _generator()
    stale = [str(p.relative_to(ROOT)) for p, text in gen.render_all().items() if not gen.up_to_date(p, text)]
    assert stale == [], "out of date: run `python docs/generate.py`"


def test_a_figure_is_stale_when_a_coordinate_moves_past_its_last_digit(tmp_path):
    same = _generator().up_to_date
    svg, page = tmp_path / "f.svg", tmp_path / "p.md"
    svg.write_text('<path d="M 39.913516 142.516562 L 1.5 2.25"/>')
    page.write_text("ADE 0.245")
    assert same(svg, '<path d="M 39.913516 142.516563 L 1.5 2.25"/>')
    assert not same(svg, '<path d="M 39.913516 142.516662 L 1.5 2.25"/>')
    assert not same(svg, '<path d="M 39.913516 142.516562 L 1.5 2.25 Z"/>')
    assert same(page, "ADE 0.245") and not same(page, "ADE 0.246") and not same(tmp_path / "none.svg", "")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """The site built once for this file's tests, warnings as errors: `(folder, the build's process)`."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    out = tmp_path_factory.mktemp("site")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-f", str(DOCS / "mkdocs.yml"),
                        "-d", str(out)], capture_output=True, text=True, timeout=300, env=dict(os.environ, NO_MKDOCS_2_WARNING="1"))
    return out, r


def test_the_site_builds_with_warnings_as_errors(site):
    _, r = site
    assert r.returncode == 0, r.stdout + r.stderr


def _widths():
    spec = importlib.util.spec_from_file_location("docs_check_widths", DOCS / "check_widths.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_results_and_benchmarks_show_figures_and_no_table_wider_than_the_page(site, tmp_path):
    """In headless Chromium at 1280 px (skipped without one: `apt-get install chromium`), the Results and
    Benchmarks pages each show at least three figures, and no table, collapsed blocks opened, is wider than the
    page's text column; the screenshots land in the test's temporary folder."""
    pytest.importorskip("mkdocs")
    widths = _widths()
    if widths.browser() is None:
        pytest.skip("no Chromium on PATH (chromium, chromium-browser, google-chrome): table widths not measured")
    site, r = site
    assert r.returncode == 0, r.stdout + r.stderr
    for page in ("results", "benchmarks"):
        m = widths.measure(site, page, 1280, screenshot=tmp_path / f"{page}.png")
        assert len(m["figures"]) >= 3, f"{page}: {m['figures']}"
        assert all((site / page / f).exists() for f in m["figures"]), f"{page}: a figure file is missing"
        assert m["tables"], f"{page}: no table measured"
        assert widths.too_wide(m) == [], f"{page}: tables wider than the {m['limit']:.0f} px text column"


def test_the_width_check_finds_a_table_wider_than_the_page(tmp_path):
    """The measurement itself: a page with a 30-column table is reported too wide, a 3-column one is not."""
    widths = _widths()
    if widths.browser() is None:
        pytest.skip("no Chromium on PATH: table widths not measured")
    (tmp_path / "page").mkdir()
    wide = "<tr>" + "".join(f"<td>column{i:02d}value</td>" for i in range(30)) + "</tr>"
    narrow = "<tr><td>a</td><td>b</td><td>c</td></tr>"
    (tmp_path / "page" / "index.html").write_text(
        f'<html><body><div class="md-content__inner" style="width: 600px"><table>{narrow}</table>'
        f'<details><summary>more</summary><table>{wide}</table></details></div></body></html>')
    m = widths.measure(tmp_path, "page", 1280)
    assert [t["index"] for t in widths.too_wide(m)] == [1]
