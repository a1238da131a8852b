"""Markdown layout for the generated pages: tables that fit the page, headline tables, collapsible blocks.

A table wider than the page's text column (about 690 px at a 1280 px window, Material's layout with both
sidebars) is split into several tables that repeat its key columns (the leading non-numeric ones);
`docs/check_widths.py` measures the result in a browser.
"""

from __future__ import annotations

import re

BUDGET_PX = 680  # the text column is ~688 px at 1280 px
CHAR_PX, CODE_PX, CELL_PAD_PX = 8.2, 8.6, 34.0  # a 13 px table font (fallback fonts run wide), 16 px padding a side
MIN_COLUMN_PX = 100.0  # Material's `th { min-width: 5rem }`
NUMERIC = re.compile(r"^[-+0-9.,:x% *]*$|^-$|^\*\*[-+0-9.,x% ]+\*\*$")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _text_px(cell: str) -> float:
    """Returns the narrowest width a cell can take: its longest unbreakable piece (a number with its +- sd stays
    whole; a line break `<br>` ends a piece; code breaks where a long word may, after `_` and `/`)."""
    if "<br>" in cell:
        return max(_text_px(part) for part in cell.split("<br>"))
    cell = re.sub(r"</?small>", "", cell)
    if NUMERIC.match(cell.replace("+-", "").replace("±", "").replace(" ", "")):
        return len(cell) * CHAR_PX
    widest = 0.0
    for code in re.findall(r"`([^`]*)`", cell):
        widest = max(widest, max(len(piece) + 1 for piece in re.split(r"[_/]", code)) * CODE_PX)
    plain = re.sub(r"`[^`]*`", " ", re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", cell))
    for word in plain.split():
        widest = max(widest, len(word) * CHAR_PX)
    return widest


def column_px(head: str, column: list[str]) -> float:
    """Returns the estimated narrowest width of a column in CSS pixels."""
    return max(MIN_COLUMN_PX, max([_text_px(head), *map(_text_px, column)]) + CELL_PAD_PX)


def key_columns(head: list[str], rows: list[list[str]]) -> int:
    """Returns how many leading columns identify a row: those holding any non-numeric cell (at least one)."""
    n = 0
    for i in range(len(head)):
        if rows and all(NUMERIC.match(r[i].replace("+-", "").replace(" ", "")) for r in rows if i < len(r)):
            break
        n += 1
    return max(1, min(n, len(head) - 1))


def split_table(lines: list[str], budget: float = BUDGET_PX) -> list[str]:
    """Returns a markdown table as one or more tables that each fit `budget` px, the key columns in each."""
    head, rows = _cells(lines[0]), [_cells(r) for r in lines[2:]]
    rows = [r + [""] * (len(head) - len(r)) for r in rows]
    widths = [column_px(h, [r[i] for r in rows]) for i, h in enumerate(head)]
    if sum(widths) <= budget:
        return lines
    keys = key_columns(head, rows)
    groups, current, used = [], [], sum(widths[:keys])
    for i in range(keys, len(head)):
        if current and used + widths[i] > budget:
            groups.append(current)
            current, used = [], sum(widths[:keys])
        current.append(i)
        used += widths[i]
    groups.append(current)
    out = []
    for g in groups:
        cols = list(range(keys)) + g
        out += ["| " + " | ".join(head[i] for i in cols) + " |", "|" + " --- |" * len(cols)]
        out += ["| " + " | ".join(r[i] for i in cols) + " |" for r in rows]
        out.append("")
    return out[:-1]


def fit_tables(text: str, budget: float = BUDGET_PX) -> str:
    """Returns `text` with every markdown table (at any indentation, outside code fences) split to fit `budget` px."""
    lines, out, i, fence = text.split("\n"), [], 0, False
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("```"):
            fence = not fence
        indent = line[: len(line) - len(line.lstrip())]
        if (not fence and line.lstrip().startswith("|") and i + 1 < len(lines)
                and re.match(r"^\s*\|( *:?-+:? *\|)+\s*$", lines[i + 1])):
            j = i + 2
            while j < len(lines) and lines[j].lstrip().startswith("|"):
                j += 1
            out += [indent + t if t else "" for t in split_table([ln.strip() for ln in lines[i:j]], budget)]
            i = j
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


def details(title: str, lines: list[str], kind: str = "note") -> list[str]:
    """Returns a collapsed block (pymdownx.details) holding `lines`."""
    return [f'??? {kind} "{title}"', "", *[("    " + ln) if ln else "" for ln in lines], ""]


def parse_tables(md: str) -> list[tuple[str, list[str], list[list[str]]]]:
    """Returns `(title, header, rows)` of each table in `md`, the title being the last non-table line before it."""
    out, title, lines = [], "", md.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("|") and i + 1 < len(lines) and lines[i + 1].startswith("| ---"):
            j = i + 2
            while j < len(lines) and lines[j].startswith("|"):
                j += 1
            out.append((title, _cells(lines[i]), [_cells(r) for r in lines[i + 2:j]]))
            i = j
            continue
        if lines[i].strip():
            title = lines[i].strip()
        i += 1
    return out


def figure(path: str, alt: str, caption: str) -> list[str]:
    """Returns a figure: the picture, then its caption (what it shows, where it comes from)."""
    return [f"![{alt}]({path})", "", f"*{caption}*", ""]
