"""Recursive-projection benchmark: K = 50 samples x 45 frames, jaxmotion (LM) vs MOJO's Adam fit (PyTorch).

    flock /tmp/jaxmotion-heavy.lock python benchmarks/projection.py [--data ../shared/data/bandai-namco-2]

Body: the skeleton body of Bandai-Namco-2 with the `bandai` (CMU-41) markers when the data is there
(else the built-in 21-joint skeleton). Targets: K = 50 real 45-frame windows of the test style
(every 2nd frame at 30 fps, i.e. 15 fps as MOJO) driving the body, plus 1 cm Gaussian noise per
marker and frame: a stand-in for a decoder's imperfect markers. Each method fits every frame
warm-started from its previous fit, shape fixed, starting from the true body of the frame before.
jaxmotion: one jitted `lax.scan` over frames of `fit_markers` (Levenberg-Marquardt), vmapped over
K; compile time is reported apart. PyTorch: MOJO's three Adam stages (10/30/20 iterations,
lr 0.008), batched over K. Both minimise MOJO's Eq. (2) (lambda_pose = 0.0005); residuals are the
mean per-marker distance to the targets, in mm, at the last frame and over all frames.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import time
from pathlib import Path

_HERE = Path(__file__).resolve().parent

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.body.fit import LAMBDA_POSE, default_solver, eq2_residuals, fit_markers
from jaxmotion.body.projection import recursive_projection

K, T = 50, 45


def bandai_targets(data: Path, rng: np.random.Generator):
    """Returns `(body, params (K, T+1) true BodyParams, clean markers (K, T+1, M, 3))` from real clips."""
    from jaxmotion.body.skeleton import params_from_bvh, skeleton_body_from_bvh
    from jaxmotion.data.datasets import bandai_clip_dir
    from jaxmotion.formats.bvh import read_bvh

    clips = sorted(bandai_clip_dir(data, None).glob("dataset-2_*_normal_*.bvh"))
    body = skeleton_body_from_bvh(read_bvh(clips[0]), "bandai")
    windows, n, i = [], 2 * (T + 1), 0
    while len(windows) < K:
        bvh = read_bvh(clips[(i * 7) % len(clips)])
        i += 1
        if bvh.num_frames <= n:  # a few clips are shorter than one window
            continue
        s = int(rng.integers(0, bvh.num_frames - n))
        windows.append(params_from_bvh(body, bvh, np.arange(s, s + n, 2)))
    params = jax.tree.map(lambda *a: jnp.stack(a), *windows)
    return body, params


def toy_targets(rng: np.random.Generator):
    """Returns the built-in skeleton and smooth random motion (no data needed)."""
    from jaxmotion.body.skeleton import toy_skeleton

    body = toy_skeleton("cmu41")
    p = body.zero_params()
    steps = 0.03 * rng.standard_normal((K, T + 1, p.pose.shape[0]))
    pose = np.cumsum(steps, axis=1) + 0.2 * rng.standard_normal((K, 1, p.pose.shape[0]))
    rep = lambda a: jnp.broadcast_to(a, (K, T + 1) + a.shape)  # noqa: E731
    return body, p._replace(
        transl=rep(p.transl) + jnp.asarray(np.cumsum(0.02 * rng.standard_normal((K, T + 1, 3)), 1), jnp.float32),
        orient=rep(p.orient), shape=rep(p.shape), pose=jnp.asarray(pose, jnp.float32), hand=rep(p.hand),
    )  # fmt: skip


def main() -> None:
    global K, T
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared/data/bandai-namco-2"))
    ap.add_argument("--noise", type=float, default=0.01, help="marker noise std (m)")
    ap.add_argument("--max-steps", type=int, default=20, help="LM steps per stage")
    ap.add_argument("--atol", type=float, default=None, help="LM step tolerance (default: fit.default_solver's)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--k", type=int, default=K, help="samples (smoke tests only; the benchmark is K = 50)")
    ap.add_argument("--t", type=int, default=T, help="frames (smoke tests only; the benchmark is 45)")
    args = ap.parse_args()
    K, T = args.k, args.t
    rng = np.random.default_rng(0)
    data = Path(args.data)
    if (data / "bandai2_dev.tar.xz").is_file() or any(data.glob("*.bvh")):
        body, true = bandai_targets(data, rng)
        source = "Bandai-Namco-2 test style, 15 fps"
    else:
        body, true = toy_targets(rng)
        source = "built-in skeleton, random smooth motion"
    clean = jax.vmap(jax.vmap(body.markers))(true)
    noisy = clean + args.noise * jnp.asarray(rng.standard_normal(clean.shape), jnp.float32)
    init = jax.tree.map(lambda a: a[:, 0], true)  # the last observed frame's body
    targets = noisy[:, 1:]  # (K, T, M, 3)
    m = body.num_markers

    # ---------------- jaxmotion: scan over frames of LM fits, vmapped over K, one jit.
    solver = default_solver() if args.atol is None else default_solver(atol=args.atol)

    def fit(t, p):
        return fit_markers(
            body, t, p, stages=("global", "body", "hands"), max_steps=args.max_steps, align=False, solver=solver
        )

    def project(targets_k, init_k):
        step = lambda carry, frame: (carry, frame.reshape(-1))  # noqa: E731  the decoder stand-in
        run = lambda t, p: recursive_projection(step, fit, (), t, p, feed_back=lambda c, f: c)  # noqa: E731
        return jax.vmap(run)(targets_k, init_k)

    jitted = jax.jit(project)
    t0 = time.perf_counter()
    out = jax.block_until_ready(jitted(targets, init))
    first = time.perf_counter() - t0
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        out = jax.block_until_ready(jitted(targets, init))
        runs.append(time.perf_counter() - t0)
    jx_time = min(runs)
    jx_markers = np.asarray(out.markers).reshape(K, T, m, 3)
    jx_params = out.params

    # ---------------- PyTorch: MOJO's Adam fit, frame by frame, batched over K.
    import torch

    spec = importlib.util.spec_from_file_location("torch_body", _HERE / "torch_body.py")
    torch_body = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(torch_body)
    TorchSkeletonBody, mojo_adam_fit = torch_body.TorchSkeletonBody, torch_body.mojo_adam_fit

    torch.set_num_threads(os.cpu_count() or 1)
    tb = TorchSkeletonBody(body)
    tt = lambda a: torch.tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    tr, orr, sh, po = tt(init.transl), tt(init.orient), tt(init.shape), tt(init.pose)
    tgt = tt(targets)
    th_markers = []
    t0 = time.perf_counter()
    for f in range(T):
        tr, orr, po = mojo_adam_fit(tb, tgt[:, f], tr, orr, sh, po, lambda_pose=LAMBDA_POSE)
        with torch.no_grad():
            th_markers.append(tb.markers(tr, orr, sh, po).numpy())
    th_time = time.perf_counter() - t0
    th_markers = np.stack(th_markers, 1)
    # Same body model: the torch markers of the JAX fit equal the JAX markers.
    last = jax.tree.map(lambda a: np.asarray(a[:, -1]), jx_params)
    check = tb.markers(tt(last.transl), tt(last.orient), tt(last.shape), tt(last.pose)).numpy()
    body_gap_mm = float(np.abs(check - jx_markers[:, -1]).max() * 1000)

    tg = np.asarray(targets)
    cl = np.asarray(clean[:, 1:])

    def stats(mk, seconds):
        d = np.linalg.norm(mk - tg, axis=-1) * 1000
        g = np.linalg.norm(mk - cl, axis=-1) * 1000
        return {
            "s_per_frame": seconds / T,
            "residual_last_mm": float(d[:, -1].mean()),
            "residual_all_mm": float(d.mean()),
            "to_clean_last_mm": float(g[:, -1].mean()),
        }

    def objective(mk_params):  # mean over samples and frames of Eq. (2)
        r = jax.vmap(jax.vmap(lambda p, t: eq2_residuals(body, p, t, jnp.ones(m))))(mk_params, targets)
        return float(np.mean(sum(np.sum(np.asarray(x) ** 2, axis=tuple(range(2, x.ndim))) for x in r)))

    res = {
        "K": K, "T": T, "max_steps": args.max_steps, "atol": solver.atol if hasattr(solver, "atol") else None, "markers": m, "joints": body.num_joints, "targets": source, "noise_m": args.noise,
        "jax": {**stats(jx_markers, jx_time), "compile_s": first - jx_time},
        "torch_adam": stats(th_markers, th_time),
        "jax_eq2_mean": objective(jx_params),
        "torch_vs_jax_body_max_mm": body_gap_mm,
        "device": f"{jax.devices()[0].platform} ({os.cpu_count()} cores)", "jax_version": jax.__version__, "torch_version": torch.__version__,
    }  # fmt: skip
    res["speedup"] = res["torch_adam"]["s_per_frame"] / res["jax"]["s_per_frame"]
    print(json.dumps(res, indent=1))
    j, t = res["jax"], res["torch_adam"]
    print(
        f"\njaxmotion LM : {1000 * j['s_per_frame']:8.2f} ms/frame (K={K})  residual last {j['residual_last_mm']:.2f} mm"
        f"  all {j['residual_all_mm']:.2f} mm  (compile {j['compile_s']:.1f} s)\n"
        f"PyTorch Adam : {1000 * t['s_per_frame']:8.2f} ms/frame (K={K})  residual last {t['residual_last_mm']:.2f} mm"
        f"  all {t['residual_all_mm']:.2f} mm\nspeed-up {res['speedup']:.1f}x"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
