"""`jaxmotion view`: the self-contained 3-D viewer page of a trained run, its structure, and that headless Chromium draws it."""

import base64
import json
import re
import shutil
import subprocess
import sys
import time

import jax
import numpy as np
import pytest

import jaxmotion
from jaxmotion import experiment
from jaxmotion.eval import metrics
from jaxmotion.tools import viewer
from jaxmotion.cli import main
from jaxmotion.config import load_config
from jaxmotion.data.synthetic import PARENTS
from jaxmotion.pictures.viz import frames_to_joints, view_axes

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
MAGENTA = np.array([0xE6, 0x00, 0x7E])  # viewer.TRUTH_COLOR


def _bones(path):
    pairs = zip(path[:-1], path[1:])
    return sorted(tuple(sorted((int(a), int(b)))) for a, b in pairs if a >= 0 and b >= 0)


@pytest.mark.parametrize("parents", [PARENTS, (-1, 0, -1, 2, 2, 0, 5)], ids=["synthetic body", "forest"])
def test_bone_path_draws_every_bone_exactly_once(parents):
    path = viewer.bone_path(parents)
    assert _bones(path) == sorted(tuple(sorted((j, p))) for j, p in enumerate(parents) if p >= 0)
    assert path[0] >= 0 and path[-1] >= 0 and not np.any((path[:-1] < 0) & (path[1:] < 0))
    if parents == PARENTS:  # 16 bones as 5 limbs: 21 points and 4 gaps instead of 16 separate 2-point segments
        assert len(path) == 25


def test_most_distinct_picks_the_farthest_from_the_reference_then_from_those_picked():
    futures = np.array([1.0, 2.0, 10.0, 9.5])[:, None]
    np.testing.assert_array_equal(viewer.most_distinct(futures, np.zeros(1), 2), [2, 1])
    assert len(viewer.most_distinct(futures, np.zeros(1), 9)) == 4


def test_missing_plotly_names_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "plotly.graph_objects", None)  # import fails as if plotly were not installed
    assert main(["view", str(tmp_path)]) == 2
    assert "pip install 'jaxmotion[viewer]'" in capsys.readouterr().err


def _figure_json(html: str):
    """Returns `(data, layout, frames)` that the page passes to `Plotly.newPlot` and `Plotly.addFrames`."""
    dec = json.JSONDecoder()

    def values(start, n):
        out, i = [], start
        for _ in range(n):
            i = re.compile(r"[\s,]*").match(html, i).end()
            v, i = dec.raw_decode(html, i)
            out.append(v)
        return out

    _, data, layout = values(html.rindex("Plotly.newPlot(") + len("Plotly.newPlot("), 3)
    (frames,) = values(html.index(",", html.rindex("Plotly.addFrames(")) + 1, 1)
    return data, layout, frames


def _points(trace) -> np.ndarray:
    """Returns a trace's `(n, 3)` points (plotly writes float32 arrays as base64 typed arrays)."""
    cols = [np.asarray(v, np.float32) if isinstance(v, list) else np.frombuffer(base64.b64decode(v["bdata"]), np.float32)
            for v in (trace[a] for a in "xyz")]
    return np.stack(cols, axis=1)


def _assert_draws(trace, joints, path, up):
    """The trace draws `joints (J, 3)` along `path`: the same `up` coordinate (plotly's z), the same distances
    (the other axes may be permuted or flipped)."""
    pts, want = _points(trace), joints[np.maximum(path, 0)]
    ok = path >= 0
    assert np.all(np.isnan(pts[~ok]))
    pts, want = pts[ok], want[ok]
    np.testing.assert_allclose(pts[:, 2], want[:, up], atol=1e-5)
    dist = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(dist(pts), dist(want), atol=1e-5)


@pytest.fixture(scope="module")
def page(tiny_cli_run, tmp_path_factory):
    """The page of the session's tiny DLow run (K = 6 and 2): 3 windows, 4 futures each."""
    cfg, work = tiny_cli_run
    out = tmp_path_factory.mktemp("view") / "page.html"
    assert main(["view", str(work), "--out", str(out), "--windows", "3", "--k", "4"]) == 0
    prep = experiment.prepare(experiment.load_data(load_config(cfg)), 40)
    return out, work, prep


@pytest.mark.slow
def test_page_holds_every_window_trace_and_frame(page, capsys):
    out, work, prep = page
    html = out.read_text()
    assert not re.search(r"<script[^>]*\bsrc=", html)  # plotly.js is embedded: the page opens offline
    assert out.stat().st_size < 8e6
    data, layout, frames = _figure_json(html)
    chosen = experiment.most_multimodal(prep, 3)
    sets = metrics.multimodal_gt(prep.x[:, -1], prep.dataset.mm_threshold, exclude_self=True)
    mm = [min(4, int(np.asarray(sets.mask)[i].sum())) for i in chosen]
    assert len(data) == sum(2 + m + 4 for m in mm)
    window_menu = layout["updatemenus"][0]
    assert [b["label"].split(" (")[0] for b in window_menu["buttons"]] == [f"window {i}" for i in chosen]
    sizes = [2 + m + 4 for m in mm]
    for w, b in enumerate(window_menu["buttons"]):  # each entry shows exactly its window's traces
        vis = np.asarray(b["args"][0]["visible"])
        assert vis.sum() == sizes[w] and vis[sum(sizes[:w]) : sum(sizes[: w + 1])].all()
    assert [t["visible"] for t in data] == [i < sizes[0] for i in range(len(data))]
    future_menu = layout["updatemenus"][2]
    assert len(future_menu["buttons"]) == 5 and future_menu["buttons"][3]["args"][0]["visible"] == [False, False, True, False]
    assert [t["name"] for t in data[: sizes[0]]][-4:] == [f"future {i}" for i in range(4)]
    # 75 frames, every 2nd one animated; the time slider steps through the same frames; every frame sets every trace.
    names = [f["name"] for f in frames]
    assert names == [str(t) for t in range(0, 75, 2)] and all(len(f["data"]) == len(data) for f in frames)
    assert [s["args"][0][0] for s in layout["sliders"][0]["steps"]] == names
    # The last frame draws window 0's true end pose and the DLow futures of K = 6 (the first 4), sampled with key(0).
    path, i = viewer.bone_path(prep.dataset.skeleton.parents), chosen[0]
    last, first = frames[-1]["data"], frames[0]["data"]
    up = view_axes(frames_to_joints(prep.windows[i]))[0]  # the axis drawn vertical: where window 0's body spans most
    _assert_draws(last[1], frames_to_joints(prep.y[i, -1]), path, up)
    want = jaxmotion.load(work).predict(prep.x[chosen], k=6, key=jax.random.key(0), method="dlow")[:, :4]
    for j in range(4):
        _assert_draws(last[2 + mm[0] + j], frames_to_joints(want[0, j, -1]), path, up)
    _assert_draws(first[0], frames_to_joints(prep.x[i, 0]), path, up)  # observed frames: the observed pose, no future yet
    assert all(len(_points(t)) == 0 for t in first[1 : sizes[0]])
    assert "the first of K=6" in layout["title"]["text"]
    # A method the run does not have is one clear line.
    assert main(["view", str(work), "--out", str(out.with_name("x.html")), "--method", "nope"]) == 2
    assert "--method nope: not a predictor of this run" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None,
                    reason="no chromium binary on PATH (Debian: apt-get install chromium): the render check needs one")
def test_headless_chromium_draws_the_ground_truth_skeleton(page, tmp_path):
    out = page[0]
    png = tmp_path / "page.png"
    t0 = time.perf_counter()
    run = subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--hide-scrollbars",
         f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1000,700", "--virtual-time-budget=8000",
         f"--screenshot={png}", out.as_uri()],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert png.is_file(), run.stderr[-2000:]
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    truth = np.abs(img - MAGENTA).max(axis=-1) <= 40
    ys, xs = np.nonzero(truth)
    # The legend's magenta sample is a few pixels high; the 3-D scene's skeleton is a body's height.
    assert truth.sum() > 300 and np.ptp(ys) > 100, f"{truth.sum()} magenta pixels; chromium: {run.stderr[-1000:]}"
    print(f"render: {time.perf_counter() - t0:.1f}s, {truth.sum()} ground-truth pixels spanning {np.ptp(ys)} px")


def test_keep_skeleton_puts_the_futures_on_the_observed_bone_lengths(page):
    from jaxmotion.tools.predictor import load
    from jaxmotion.tools.viewer import window_views

    _, work, prep = page
    model, windows = load(work), np.array([0, 5])
    raw, _ = window_views(model, prep, windows, k=4, method="dlow", key=jax.random.key(0))
    kept, _ = window_views(model, prep, windows, k=4, method="dlow", key=jax.random.key(0), keep_skeleton=True)
    par = np.array(prep.dataset.skeleton.parents)
    bones = lambda p: p[..., 1:, :] - p[..., par[1:], :]  # noqa: E731
    for r, v in zip(raw, kept):
        want = np.linalg.norm(bones(v.observed[-1]), axis=-1)
        np.testing.assert_allclose(np.linalg.norm(bones(v.futures), axis=-1), np.broadcast_to(want, v.futures.shape[:2] + want.shape), atol=1e-5)
        cos = np.sum(bones(v.futures) * bones(r.futures), -1) / np.linalg.norm(bones(v.futures), axis=-1) / np.linalg.norm(bones(r.futures), axis=-1)
        assert cos.min() > 1 - 1e-5
