"""A 3-D viewer page of a trained run: test windows, their K futures and the multimodal ground truth, in one HTML file.

    jaxmotion view runs/dlow_synthetic                       # writes runs/dlow_synthetic/view.html
    jaxmotion view RUN_DIR --out page.html --windows 4 --k 20 --method cvae
    jaxmotion view RUN_DIR --keep-skeleton                   # futures on each window's observed bone lengths

The page is one self-contained file (plotly's JavaScript is embedded, nothing is fetched when it is
opened). It shows one test window at a time in plotly's 3-D scene (drag to rotate, scroll to zoom):
the observed frames (grey), then the ground truth (magenta), the K predicted futures (viridis
colours) and up to `mm` multimodal ground-truth futures (orange, dashed: the futures of the other
test windows whose last observed pose is within the dataset's threshold, [protocol §2][metrics]). Play /
Pause and a time slider animate the motion; a dropdown per window shows all K futures overlaid or
one of them; another shows or hides the ground truth and the multimodal ground truth (clicking a
legend entry toggles one trace); the window dropdown chooses among the `windows` most multimodal test windows
(`experiment.most_multimodal`: the ones whose multimodal ground-truth futures spread most).

Defaults, chosen to keep the file small (6.6 MB on the synthetic data, 4.8 MB of it plotly.js):
6 windows, 10 futures each, up to 4 multimodal ground-truth futures each (the most distinct ones,
`most_distinct`), at most 40 animation frames per window (every 2nd frame of a 15 -> 60 window);
every further window adds about 0.3 MB at these settings (17 joints). A method with one network per K (DLow's
Q networks) draws at the smallest trained K that is at least `k` and shows the first `k` of those
futures, or at its largest K when `k` is above every trained K (the page title says which). Poses
are frame vectors drawn as `viz.frames_to_joints` does (root-relative, the root at the origin); the
axis the body spans most (`viz.view_axes`) is drawn vertical.

Needs plotly >= 6 (`pip install 'jaxmotion[viewer]'`), imported only when a page is built: the
page's arrays are plotly.js typed arrays (base64 float32: 5.3 bytes a number; plotly.js >= 2.28).
"""

from __future__ import annotations

import base64
import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.errors import DataError
from jaxmotion.formats.atomic import atomic_path
from jaxmotion.tools.predictor import MotionPredictor, run_config
from jaxmotion.pictures.viz import frames_to_joints, view_axes

TRUTH_COLOR = "#e6007e"  # magenta: no future (viridis) or multimodal future (orange) is drawn in it
OBSERVED_COLOR = "#9a9a9a"
MM_COLOR = "#e69f00"
# The ground-truth menu: (label, truth shown, multimodal futures shown); the first two when a window has no MM future.
TRUTH_CHOICES = [("truth + multimodal truth", True, True), ("no truth", False, False), ("truth only", True, False),
                 ("multimodal truth only", False, True)]  # fmt: skip
INSTALL_HINT = "jaxmotion view needs plotly: pip install 'jaxmotion[viewer]'"


@dataclasses.dataclass
class WindowView:
    """One test window as joint positions `(..., J, 3)` in metres: what the page draws for it."""

    index: int  # among the prepared test windows
    sequence: int
    start: int
    observed: np.ndarray  # (t_his, J, 3)
    truth: np.ndarray  # (t_pred, J, 3)
    futures: np.ndarray  # (K, t_pred, J, 3)
    mm: np.ndarray  # (M, t_pred, J, 3) multimodal ground-truth futures shown (the window's own truth excluded)
    mm_total: int  # size of the window's multimodal set without itself


def bone_path(parents: tuple[int, ...] | list[int]) -> np.ndarray:
    """Returns joint indices that draw every bone `parent(j) -> j` as polylines, -1 between polylines.

    Each polyline follows first children down from a root or a branch, so one line per limb instead
    of one per bone (a 17-joint body is 26 points, 16 bones as separate segments would be 48).
    """
    parents = [int(p) for p in parents]
    children: list[list[int]] = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            children[p].append(j)
    path: list[int] = []
    for j, p in enumerate(parents):
        if p < 0 or (children[p][0] == j and parents[p] >= 0):
            continue  # not a bone, or it continues its parent's polyline
        line = [p, j]
        while children[line[-1]]:
            line.append(children[line[-1]][0])
        path += ([-1] if path else []) + line
    return np.asarray(path, np.int64)


def most_distinct(futures: np.ndarray, reference: np.ndarray, m: int) -> np.ndarray:
    """Returns indices of `m` of `futures` `(n, ...)` chosen greedily, each the farthest from `reference` and those chosen."""
    flat = futures.reshape(len(futures), -1)
    dist = np.linalg.norm(flat - reference.reshape(1, -1), axis=1)
    chosen: list[int] = []
    for _ in range(min(m, len(flat))):
        i = int(np.argmax(np.where(np.isin(np.arange(len(flat)), chosen), -np.inf, dist)))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(flat - flat[i], axis=1))
    return np.asarray(chosen, np.int64)


def sampling_k(model: MotionPredictor, k: int, method: str) -> int:
    """Returns the K to draw `k` futures with `method` at: `k` where it has a predictor there, else the smallest trained K
    above `k`, else the largest trained K (fewer than `k` futures are then shown)."""
    if method in model.predictors(k):
        return k
    trained = [kk for kk in sorted(model.config.eval_k) if method in model.predictors(kk)]
    if not trained:
        raise ValueError(
            f"--method {method}: not a predictor of this run; at K={model.default_k} it has {model.methods}"
        )
    return next((kk for kk in trained if kk >= k), trained[-1])


def window_views(
    model: MotionPredictor,
    prep: experiment.Prepared,
    windows: np.ndarray,
    *,
    k: int,
    method: str,
    key: jax.Array,
    mm: int = 4,
    keep_skeleton: bool = False,
) -> tuple[list[WindowView], int]:
    """Returns the views of test windows `windows` (indices `(n,)` into `prep`) and the K their futures were drawn at.

    `keep_skeleton`: each future is put on its window's bone lengths (its last observed frame; every
    predicted bone keeps its direction, `metrics.motion_transfer`), as `jaxmotion predict` writes them.
    """
    ds = prep.dataset
    kk = sampling_k(model, k, method)
    futures = model.predict(prep.x[windows], k=kk, key=key, method=method)[:, :k]  # (n, min(k, kk), t_pred, D)
    if keep_skeleton:
        last = jnp.asarray(prep.x[windows][:, -1][:, None, None])
        futures = np.asarray(metrics.motion_transfer(jnp.asarray(futures), last, tuple(int(p) for p in ds.skeleton.parents)))
    sets = metrics.multimodal_gt(prep.x[:, -1], ds.mm_threshold, exclude_self=True)
    idx, mask = np.asarray(sets.idx), np.asarray(sets.mask)
    views = []
    for n, i in enumerate(int(w) for w in windows):
        others = idx[i][mask[i]]
        pick = others[most_distinct(prep.y[others], prep.y[i], mm)] if len(others) else others
        views.append(WindowView(
            index=i, sequence=int(prep.seq_index[i]), start=int(prep.starts[i]),
            observed=frames_to_joints(prep.x[i]), truth=frames_to_joints(prep.y[i]),
            futures=frames_to_joints(futures[n]),
            mm=frames_to_joints(prep.y[pick]) if len(pick) else np.zeros((0, ds.t_pred, ds.skeleton.num_joints, 3)),
            mm_total=len(others),
        ))  # fmt: skip
    return views, kk


def _plotly():
    try:
        import plotly.graph_objects as go
    except ModuleNotFoundError:
        raise ModuleNotFoundError(INSTALL_HINT, name="plotly") from None
    return go


def _scene_axes(joints: np.ndarray) -> tuple[list[int], float]:
    """Returns the data axes drawn as plotly's (x, y, z), up last, and the sign of y that keeps the body's handedness."""
    up, across, depth = view_axes(joints)
    order = [across, depth, up]
    even = sum(order[a] > order[b] for a in range(3) for b in range(a + 1, 3)) % 2 == 0
    return order, 1.0 if even else -1.0


def figure(
    views: list[WindowView],
    parents: tuple[int, ...],
    *,
    fps: float,
    title: str = "",
    max_frames: int = 40,
):
    """Returns the page's plotly figure as a dict (module docstring): 2 + M + K traces per window, one frame per time step shown.

    Trace order per window: observed, ground truth, the M multimodal futures, the K futures; all
    windows' traces are in the figure and the window dropdown makes one window's visible.
    """
    go = _plotly()
    if not views:
        raise ValueError("viewer.figure: no window to show")
    t_his, t_pred = len(views[0].observed), len(views[0].truth)
    total = t_his + t_pred
    stride = max(1, int(np.ceil(total / max_frames)))
    times = sorted(set(range(0, total, stride)) | {t_his - 1, total - 1})
    path = bone_path(parents)
    gap = path < 0
    order, flip = _scene_axes(np.concatenate([views[0].observed, views[0].truth]))

    def xyz(pose):  # (J, 3) -> polyline coordinates with NaN gaps, float32 (plotly writes them as compact typed arrays)
        pts = pose[np.where(gap, 0, path)][:, order].astype(np.float32)
        pts[:, 1] *= flip
        pts[gap] = np.nan
        return {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}

    empty = {"x": np.zeros(0, np.float32), "y": np.zeros(0, np.float32), "z": np.zeros(0, np.float32)}

    def poses(v: WindowView, t: int) -> list[dict]:  # every trace of window v at time t
        obs = xyz(v.observed[min(t, t_his - 1)])
        if t < t_his:
            return [obs, empty] + [empty] * (len(v.mm) + len(v.futures))
        s = t - t_his
        return [obs, xyz(v.truth[s])] + [xyz(f[s]) for f in v.mm] + [xyz(f[s]) for f in v.futures]

    traces, spans, first = [], [], []
    for w, v in enumerate(views):
        first.append(len(traces))
        k = len(v.futures)
        colors = _viridis(k)
        start = poses(v, times[-1])
        style = [("observed (then its last pose)", dict(color=OBSERVED_COLOR, width=4), True, None)]
        style.append(("ground truth", dict(color=TRUTH_COLOR, width=7), True, None))
        style += [(f"multimodal ground truth ({len(v.mm)} of {v.mm_total})", dict(color=MM_COLOR, width=3, dash="dash"),
                   m == 0, f"mm{w}") for m in range(len(v.mm))]  # fmt: skip
        style += [(f"future {i}", dict(color=colors[i], width=4), True, None) for i in range(k)]
        for (name, line, legend, group), d in zip(style, start):
            traces.append(go.Scatter3d(**d, mode="lines", name=name, line=line, showlegend=legend, legendgroup=group,
                                       visible=w == 0, hoverinfo="name", connectgaps=False))
        every = np.concatenate([v.observed, v.truth, *v.futures, *v.mm])[..., order]
        lo, hi = every.min(axis=(0, 1)), every.max(axis=(0, 1))
        centre, half = (lo + hi) / 2, 0.55 * float((hi - lo).max())
        centre[1] *= flip
        spans.append([[float(c - half), float(c + half)] for c in centre])
    n_traces = len(traces)
    ends = first[1:] + [n_traces]

    # Frames as plain dicts with typed arrays: building thousands of validated `go.Frame` traces costs seconds.
    def frame_trace(d):
        return {"type": "scatter3d", **{a: _typed(c) for a, c in d.items()}}

    frames = [{"name": str(t), "data": [frame_trace(d) for v in views for d in poses(v, t)]} for t in times]
    ms = int(round(1000 * stride / fps))
    steps = [dict(method="animate", label=f"{(t - t_his + 1) / fps:+.2f}",
                  args=[[str(t)], dict(mode="immediate", frame=dict(duration=0, redraw=True), transition=dict(duration=0))])
             for t in times]  # fmt: skip
    n = len(views)

    def menus_visible(w):  # the future and truth menus of window w only
        return {f"updatemenus[{2 + j}].visible": j % n == w for j in range(2 * n)} | {
            f"updatemenus[{2 + w}].active": 0, f"updatemenus[{2 + n + w}].active": 0}

    def window_title(v):
        return f"{title}<br><sub>test window {v.index} (sequence {v.sequence}, start frame {v.start}): " \
               f"{len(v.futures)} futures, {len(v.mm)} of its {v.mm_total} multimodal ground-truth futures</sub>"

    def ranges(w):
        return {f"scene.{a}axis.range": spans[w][i] for i, a in enumerate("xyz")}

    window_menu = dict(
        type="dropdown", direction="down", x=0.0, y=1.0, xanchor="left", yanchor="top", active=0, showactive=True,
        buttons=[dict(method="update", label=f"window {v.index} (seq {v.sequence}, frame {v.start})",
                      args=[{"visible": [first[w] <= i < ends[w] for i in range(n_traces)]},
                            {"title.text": window_title(v), **ranges(w), **menus_visible(w)}])
                 for w, v in enumerate(views)],
    )  # fmt: skip
    play_menu = dict(
        type="buttons", direction="left", x=0.0, y=0.06, xanchor="left", yanchor="top", showactive=False,
        buttons=[dict(label="Play", method="animate",
                      args=[None, dict(frame=dict(duration=ms, redraw=True), transition=dict(duration=0), fromcurrent=True)]),
                 dict(label="Pause", method="animate",
                      args=[[None], dict(frame=dict(duration=0, redraw=False), mode="immediate", transition=dict(duration=0))])],
    )  # fmt: skip
    future_menus, truth_menus = [], []
    for w, v in enumerate(views):
        k, m = len(v.futures), len(v.mm)
        fut = list(range(first[w] + 2 + m, first[w] + 2 + m + k))
        future_menus.append(dict(
            type="dropdown", direction="down", x=0.0, y=0.93, xanchor="left", yanchor="top", active=0, visible=w == 0,
            buttons=[dict(method="restyle", label=f"all {k} futures", args=[{"visible": [True] * k}, fut])]
            + [dict(method="restyle", label=f"future {i} only", args=[{"visible": [j == i for j in range(k)]}, fut])
               for i in range(k)],
        ))  # fmt: skip
        gt = list(range(first[w] + 1, first[w] + 2 + m))
        truth_menus.append(dict(
            type="dropdown", direction="down", x=0.0, y=0.86, xanchor="left", yanchor="top", active=0, visible=w == 0,
            buttons=[dict(method="restyle", label=label, args=[{"visible": [truth] + [mmv] * m}, gt])
                     for label, truth, mmv in TRUTH_CHOICES[: 4 if m else 2]],
        ))  # fmt: skip
    fig = go.Figure(data=traces)
    axis = dict(showbackground=True, backgroundcolor="#f4f4f8", gridcolor="#d8d8e0", zerolinecolor="#c0c0c8")
    names = ["x", "y", "z"]
    fig.update_layout(
        template="plotly_white",
        title=dict(text=window_title(views[0]), x=0.5, font=dict(size=14)),
        margin=dict(l=0, r=0, t=70, b=70),
        scene=dict(
            aspectmode="cube",
            camera=dict(eye=dict(x=1.5, y=-1.5, z=0.6), up=dict(x=0, y=0, z=1)),
            **{f"{a}axis": dict(axis, range=spans[0][i], title=f"{'-' if i == 1 and flip < 0 else ''}{names[order[i]]} (m)")
               for i, a in enumerate("xyz")},
        ),  # fmt: skip
        legend=dict(x=1.0, xanchor="right", y=0.95, bgcolor="rgba(255,255,255,0.7)", font=dict(size=11)),
        updatemenus=[window_menu, play_menu] + future_menus + truth_menus,
        sliders=[dict(active=len(times) - 1, steps=steps, x=0.12, len=0.86, y=0.06, yanchor="top", font=dict(size=9),
                      currentvalue=dict(prefix="seconds after the last observed frame: ", font=dict(size=12)),
                      pad=dict(t=10))],
    )  # fmt: skip
    return {**fig.to_dict(), "frames": frames}


def _typed(a: np.ndarray) -> dict:
    """Returns plotly.js's typed-array form of a float32 array (base64 of its little-endian bytes; plotly.js >= 2.28)."""
    return {"dtype": "f4", "bdata": base64.b64encode(np.ascontiguousarray(a, "<f4").tobytes()).decode("ascii")}


def _viridis(k: int) -> list[str]:
    from plotly.colors import sample_colorscale

    return sample_colorscale("Viridis", list(np.linspace(0.0, 0.9, k)) if k > 1 else [0.0])


def write_page(fig: dict, path: str | Path) -> Path:
    """Writes the figure `fig` (`figure`) as one self-contained HTML file (plotly.js embedded) and returns its path."""
    import plotly.io as pio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        pio.write_html(fig, tmp, validate=False, include_plotlyjs=True, full_html=True, auto_play=False,
                       config={"displaylogo": False, "responsive": True})
    return path


def run_data(source: str, run_dir: str | Path) -> str:
    """Returns the run's data source as a path that exists: as recorded, else relative to the run or a folder above it.

    A run records the path it was trained with, often relative to the folder training started in;
    raises `DataError` saying to pass `--data` when none of those exists.
    """
    if source == "synthetic" or str(source).startswith("amass:"):
        return source
    p = Path(source).expanduser()
    if p.exists():
        return str(p)
    run_dir = Path(run_dir).absolute()
    for base in (run_dir, *run_dir.parents):
        if not p.is_absolute() and (base / p).exists():
            return str(base / p)
    raise DataError(source, f"the data {Path(run_dir) / 'predictor.json'} records is not found from here ({Path.cwd()}) nor "
                            "relative to the run or a folder above it; pass --data PATH")


def view_run(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    windows: int = 6,
    k: int = 10,
    method: str | None = None,
    mm: int = 4,
    max_frames: int = 40,
    seed: int = 0,
    config: str | None = None,
    data: str | None = None,
    test_files: list[str] | None = None,
    keep_skeleton: bool = False,
) -> list[str]:
    """Writes the viewer page of the trained run `run_dir` (default `run_dir/view.html`) and returns what it wrote.

    The run's `predictor.json` supplies the predictor and, unless `config` / `data` are given, the
    config and the data source that rebuild its protocol test windows (`experiment.load_data`,
    `experiment.prepare`).
    """
    from jaxmotion.config import load_config
    from jaxmotion.tools.predictor import load

    for name, v in (("windows", windows), ("k", k), ("max_frames", max_frames)):
        if v < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    if mm < 0:
        raise ValueError(f"mm must be >= 0, got {mm}")
    _plotly()  # before the slow part
    model = load(run_dir)
    run_cfg, source = run_config(run_dir)
    cfg = experiment.resolve(load_config(config)) if config else run_cfg
    ds = experiment.load_data(cfg, data or run_data(source, run_dir), test_files)
    want = (model.dim, model.t_his, model.t_pred, list(model.skeleton.names))
    have = (ds.dim, ds.t_his, ds.t_pred, list(ds.skeleton.names))
    if want != have:
        raise DataError(data or source, f"its layout (D, t_his, t_pred) = {have[:3]} with {len(have[3])} joints does not "
                        f"match the run's {want[:3]} with {len(want[3])} joints ({Path(run_dir) / 'predictor.json'})")
    prep = experiment.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    method = method or model.main_method()
    chosen = experiment.most_multimodal(prep, windows)
    views, kk = window_views(model, prep, chosen, k=k, method=method, key=jax.random.key(seed), mm=mm, keep_skeleton=keep_skeleton)
    shown = len(views[0].futures)
    note = f" (the first of K={kk})" if kk > shown else f" (the run's largest K; --k {k} asked for more)" if shown < k else ""
    drawn = f"{shown} futures{note}" + (" on the observed bone lengths" if keep_skeleton else "")
    title = f"{ds.name}: {method}, {drawn}; {ds.t_his} observed -> {ds.t_pred} predicted frames at {round(ds.fps, 2):g} fps"
    fig = figure(views, ds.skeleton.parents, fps=ds.fps, title=title, max_frames=max_frames)
    path = write_page(fig, Path(out) if out else Path(run_dir) / "view.html")
    return [
        f"run: {run_dir} ({ds.name}, {model.config.method}); method {method}, {drawn}",
        f"windows: {len(views)} most multimodal of {len(prep.windows)} test windows: {[v.index for v in views]}",
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, {len(fig['frames'])} frames, {len(fig['data'])} traces)",
    ]
