"""Measures the built site's pages in headless Chromium at a desktop width: every table must fit its page, and
the pages' figures are counted.

    python docs/check_widths.py SITE_DIR [--pages results benchmarks] [--width 1280] [--screenshots DIR]

SITE_DIR is the output of `mkdocs build -f docs/mkdocs.yml -d SITE_DIR`. Each page is opened with its
collapsible blocks opened; a table is too wide when its content is wider than the table's box (it scrolls
sideways) or than the page's text column. Prints one line per page and exits 1 when a table is too wide;
`--screenshots` also writes each page as `PAGE.png` (the whole page, at that width). Exit status 2: no
Chromium (`chromium`, `chromium-browser`, `google-chrome`) on PATH.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
MARK = "jaxmotion-widths"
# Runs after the page's own scripts: opens every <details>, then records each table's widths and the figures.
PROBE = """<script>
window.addEventListener("load", () => {
  document.querySelectorAll("details").forEach(d => d.open = true);
  const column = document.querySelector(".md-content__inner") || document.body;
  const limit = column.getBoundingClientRect().width;
  const tables = [...column.querySelectorAll("table")].map((t, i) => ({
    index: i, head: (t.querySelector("tr") || t).innerText.replace(/\\s+/g, " ").slice(0, 80),
    content: t.scrollWidth, box: t.clientWidth, limit: limit}));
  const figures = [...column.querySelectorAll("img")].map(im => im.getAttribute("src"));
  const out = document.createElement("pre");
  out.id = "MARK";
  out.textContent = JSON.stringify({tables, figures, limit});
  document.body.appendChild(out);
});
</script>""".replace("MARK", MARK)


def browser() -> str | None:
    """Returns the path of a Chromium on PATH, or None."""
    return next((p for p in map(shutil.which, BROWSERS) if p), None)


def _chromium(exe: str, *args: str, timeout: int = 120) -> str:
    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--disable-dev-shm-usage",
           "--allow-file-access-from-files", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=True).stdout


def measure(site: Path, page: str, width: int = 1280, screenshot: Path | None = None, exe: str | None = None) -> dict:
    """Returns `{"tables": [...], "figures": [...], "limit": px}` of `site/page/index.html` at `width` px; each table
    `{"index", "head", "content", "box", "limit"}` in CSS pixels."""
    exe = exe or browser()
    if exe is None:
        raise FileNotFoundError("no Chromium on PATH")
    src = site / page / "index.html"
    html = src.read_text()
    with tempfile.NamedTemporaryFile("w", suffix=".html", dir=src.parent, delete=False) as f:
        f.write(html.replace("</body>", PROBE + "</body>", 1))
        probe = Path(f.name)
    try:
        dom = _chromium(exe, f"--window-size={width},900", "--virtual-time-budget=5000", "--dump-dom", probe.as_uri())
        if screenshot is not None:
            # A tall window: the whole page in one picture (Chromium's headless screenshot is the window).
            _chromium(exe, f"--window-size={width},12000", "--virtual-time-budget=5000", f"--screenshot={screenshot}",
                      src.as_uri())
    finally:
        probe.unlink()
    m = re.search(rf'<pre id="{MARK}">(.*?)</pre>', dom, re.S)
    if m is None:
        raise RuntimeError(f"{src}: the probe did not run")
    return json.loads(m.group(1).replace("&quot;", '"').replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&"))


def too_wide(result: dict, slack: int = 1) -> list[dict]:
    """Returns the tables whose content is wider than their box or than the text column."""
    return [t for t in result["tables"] if t["content"] > t["box"] + slack or t["content"] > t["limit"] + slack]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("site", type=Path)
    ap.add_argument("--pages", nargs="+", default=["results", "benchmarks"])
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--screenshots", type=Path, default=None)
    args = ap.parse_args(argv)
    exe = browser()
    if exe is None:
        print("no Chromium on PATH: nothing measured", file=sys.stderr)
        return 2
    if args.screenshots:
        args.screenshots.mkdir(parents=True, exist_ok=True)
    bad = 0
    for page in args.pages:
        shot = args.screenshots / f"{page}.png" if args.screenshots else None
        r = measure(args.site, page, args.width, shot, exe)
        wide = too_wide(r)
        bad += len(wide)
        print(f"{page}: {len(r['tables'])} tables, {len(r['figures'])} figures, text column {r['limit']:.0f} px at "
              f"{args.width} px; too wide: {len(wide)}")
        for t in wide:
            print(f"  table {t['index']} ({t['head']!r}): {t['content']} px of content in {t['box']} px")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
