"""The documentation's plots, drawn from the committed result files (`docs/generate.py` writes them to
`docs/pages/figures/`). Each function takes the parsed JSON it plots and returns the SVG text; the SVG is
byte-for-byte reproducible (no date, fixed ids, text kept as text), so `generate.py --check` compares it.
"""

from __future__ import annotations

import io

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STYLE = {"svg.hashsalt": "jaxmotion", "svg.fonttype": "none", "font.size": 9, "axes.spines.top": False,
         "axes.spines.right": False, "axes.grid": True, "grid.alpha": 0.3, "legend.frameon": False}


def _svg(fig) -> str:
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return buf.getvalue()


def _apd_panels(fig, axes, errors: tuple[str, str], title: str, ncol: int, fontsize: float) -> str:
    """Labels two panels of APD against an error each (`errors`), titles the figure, puts the legend below it."""
    for ax, err in zip(axes, errors):
        ax.set_xlabel(f"{err} (m), lower is better")
    axes[0].set_ylabel("APD (m), higher is more diverse")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.legend(loc="upper center", ncol=ncol, fontsize=fontsize, bbox_to_anchor=(0.5, 0.0))
    return _svg(fig)


def apd_ade(points: list[tuple[str, float, float, float, float]], title: str) -> str:
    """A scatter of accuracy against diversity: `points` are `(label, ADE, APD, MMADE, FDE)`; a label's first word
    (the method) picks the colour, the rest of it the marker."""
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(8.2, 3.6), sharey=True)
        methods = list(dict.fromkeys(p[0].split()[0].split("'")[0] for p in points))
        markers = "osD^v<>Pp*"
        seen: dict[str, int] = {}
        for p in points:
            m = p[0].split()[0].split("'")[0]
            seen[m] = seen.get(m, -1) + 1
            style = dict(s=32, color=f"C{methods.index(m) % 10}", marker=markers[seen[m] % len(markers)], zorder=3)
            for ax, i in zip(axes, (1, 3)):
                ax.scatter(p[i], p[2], label=p[0] if ax is axes[0] else None, **style)
        return _apd_panels(fig, axes, ("ADE", "MMADE"), title, ncol=3, fontsize=7.5)


def paper_and_ours(rows: list[tuple[str, dict[str, float], dict[str, float] | None]], title: str) -> str:
    """Each published row beside ours: `rows` are `(label, paper's metrics, ours or None)` with APD, ADE and FDE; the
    paper's row is a hollow marker, ours a filled one of the same colour, an arrow from the paper's to ours."""
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(8.2, 3.6), sharey=True)
        for i, (label, paper, ours) in enumerate(rows):
            color = f"C{i % 10}"
            for ax, err in zip(axes, ("ADE", "FDE")):
                ax.scatter(paper[err], paper["APD"], s=40, facecolors="none", edgecolors=color, zorder=3,
                           label=f"{label}, paper" if ax is axes[0] else None)
                if ours is not None:
                    ax.scatter(ours[err], ours["APD"], s=32, color=color, zorder=4,
                               label=f"{label}, jaxmotion" if ax is axes[0] else None)
                    ax.annotate("", xy=(ours[err], ours["APD"]), xytext=(paper[err], paper["APD"]),
                                arrowprops=dict(arrowstyle="->", color=color, lw=0.9))
        return _apd_panels(fig, axes, ("ADE", "FDE"), title, ncol=4, fontsize=7)


def learning_curves(curves: list[tuple[str, list[dict]]]) -> str:
    """Validation ADE and MMADE against training steps, one panel per run: `curves` are `(label, points)`, each
    point `{"step", "ADE", "MMADE"}` (the run's last stage)."""
    with plt.rc_context(STYLE):
        cols = 3
        rows = (len(curves) + cols - 1) // cols
        fig, axes = plt.subplots(rows, cols, figsize=(8.2, 2.5 * rows), squeeze=False)
        for ax, (label, pts) in zip(axes.flat, curves):
            steps = [p["step"] for p in pts]
            for key, color in (("ADE", "C0"), ("MMADE", "C1")):
                ax.plot(steps, [p[key] for p in pts], color=color, label=key, lw=1.2)
            ax.set_title(label, fontsize=8.5)
            ax.set_yscale("log")  # the first evaluation (untrained) is far above the rest
            for axis in (ax.yaxis.set_major_formatter, ax.yaxis.set_minor_formatter):
                axis(matplotlib.ticker.FormatStrFormatter("%.2g"))
            ax.set_xlabel("training step")
            ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
        for ax in list(axes.flat)[len(curves):]:
            ax.set_visible(False)
        axes[0][0].set_ylabel("validation error (m, log scale)")
        axes[0][0].legend(fontsize=7.5)
        fig.tight_layout()
        return _svg(fig)


def against(x_key: str, x_label: str, rows: list[dict], panels: list[tuple[str, list[str]]], title: str,
            log_x: bool = False) -> str:
    """Metrics against one setting (K, DDIM steps): one panel per `(y label, keys)`."""
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, len(panels), figsize=(8.2, 3.0), squeeze=False)
        xs = [r[x_key] for r in rows]
        for ax, (ylabel, keys) in zip(axes[0], panels):
            for key in keys:
                ax.plot(xs, [r[key] for r in rows], marker="o", ms=3, lw=1.2, label=key)
            ax.set_xlabel(x_label)
            ax.set_ylabel(ylabel)
            if log_x:
                ax.set_xscale("log")
            if len(keys) > 1:
                ax.legend(fontsize=7.5)
        fig.suptitle(title, fontsize=9)
        fig.tight_layout()
        return _svg(fig)


def latency(series: dict[str, list[tuple[float, float]]], x_label: str, title: str) -> str:
    """Latency against a size, log-log: `series` maps a label ("DLow, jaxmotion") to `(x, milliseconds)` points;
    labels sharing a method share a colour, PyTorch dashed."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6.4, 3.6))
        methods = sorted({label.split(",")[0] for label in series})
        for label, pts in series.items():
            c = f"C{methods.index(label.split(',')[0])}"
            ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", ms=3, lw=1.2, color=c,
                    ls="--" if "PyTorch" in label else "-", label=label)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(x_label)
        ax.set_ylabel("milliseconds per call")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7.5, loc="upper left")
        return _svg(fig)


def time_to_quality(curves: dict[str, list[dict]], title: str) -> str:
    """Validation error against wall-clock seconds and against steps: `curves` maps a framework to its points
    `{"step", "train_s", "val"}`."""
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2, figsize=(8.2, 3.2), sharey=True)
        for n, (label, pts) in enumerate(curves.items()):
            for ax, key in zip(axes, ("train_s", "step")):
                ax.plot([p[key] for p in pts], [p["val"] for p in pts], color=f"C{n}", lw=1.2, label=label)
        axes[0].set_xlabel("training seconds (compilation excluded)")
        axes[1].set_xlabel("training step")
        axes[0].set_ylabel("validation error (m)")
        axes[0].set_yscale("log")
        for axis in (axes[0].yaxis.set_major_formatter, axes[0].yaxis.set_minor_formatter):
            axis(matplotlib.ticker.FormatStrFormatter("%.2g"))
        axes[0].legend(fontsize=7.5)
        fig.suptitle(title, fontsize=9)
        fig.tight_layout()
        return _svg(fig)


def ratios(cases: list[tuple[str, float]], title: str) -> str:
    """Horizontal bars of speed ratios (PyTorch time / jaxmotion time), a line at 1."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6.4, 0.28 * len(cases) + 0.9))
        names = [c[0] for c in cases][::-1]
        vals = [c[1] for c in cases][::-1]
        ax.barh(names, vals, color=["C0" if v >= 1 else "C3" for v in vals])
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_xlabel("PyTorch eager time / jaxmotion time (median of three runs; > 1: jaxmotion faster)")
        ax.set_title(title, fontsize=9)
        ax.grid(axis="y", visible=False)
        return _svg(fig)
