"""Time to quality: DLow's CVAE on Bandai-Namco-2, jaxmotion against its PyTorch twin, trained the same way.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/time_to_quality.py           # ~12 min on the 2-core CPU
    python benchmarks/time_to_quality.py --steps 40 --every 20 --val-windows 64        # smoke test
    python benchmarks/time_to_quality.py --seed 1 --out /tmp/ttq_seed1.json            # another initialisation, noise and batch stream

Both sides train the CVAE of `experiments/configs/dlow_bandai.py` (nz 128, beta 0.3, lambda_v 1000,
Adam at lr 1e-3 with the config's schedule over `--steps`, batch 64) on the same stream of training
batches (jaxmotion's window sampler, numpy, one seed: the identical windows in the same order), each
initialised by its own framework's rule (PyTorch's `nn.Linear` / `nn.GRU`, which jaxmotion's
layers follow, nn/linear.py and nn/gru.py). Every `--every` steps each evaluates the **validation
reconstruction**: the mean over frames of the per-frame error ||y_rec - y|| (metres, the ADE
convention of protocol §2 (docs/pages/protocol.md#metrics)) of the posterior-mean reconstruction (z = mu) of `--val-windows`
evenly spaced test windows. That is a fixed yardstick of how well the CVAE has learnt, not its
training objective, and nothing is tuned on it.

Each framework runs in its own process, one after the other (the figures mean something only on a
quiet machine, hence the lock). The clock counts the training loop: drawing the batch on the host,
moving it, the step; evaluations are timed apart and excluded. jaxmotion's compilation is reported
apart and included in a second figure. The result is the wall time until the validation
reconstruction first reaches each of the fixed thresholds `THRESHOLDS`; the headline is the lowest
threshold both reach. Writes `benchmarks/results/time_to_quality.json`.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import machine  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "bandai-namco-2"
CONFIG = ROOT / "experiments" / "configs" / "dlow_bandai.py"
THRESHOLDS = (0.50, 0.40, 0.30, 0.25, 0.20, 0.15, 0.12, 0.10, 0.09, 0.08, 0.07, 0.06, 0.05)  # metres, fixed before any run


def _setup(data: Path, val_windows: int):
    """Returns `(cfg, cvae settings, sampler, validation windows (n, t_total, D))` as both workers see them."""
    from jaxmotion import experiment
    from jaxmotion.config import load_config

    cfg = experiment.resolve(load_config(str(CONFIG)))
    ds = experiment.load_data(cfg, str(data))
    prep = experiment.prepare(ds)
    sel = np.linspace(0, len(prep.x) - 1, min(val_windows, len(prep.x))).round().astype(int)
    val = np.concatenate([prep.x[sel], prep.y[sel]], axis=1).astype(np.float32)
    return cfg, cfg.method_config.cvae, prep.sampler, val, ds


def _val_error(y_rec: np.ndarray, y: np.ndarray) -> float:
    return float(np.mean(np.linalg.norm(y_rec - y, axis=-1)))


def jax_worker(args) -> dict:
    import functools

    import jax
    import jax.numpy as jnp

    from jaxmotion.train.compile_time import CompileTimer
    from jaxmotion.methods.common import adam
    from jaxmotion.models import dlow
    from jaxmotion.nn.execution import Execution
    from jaxmotion.train.loop import create_state, make_train_step

    _, c, sampler, val, ds = _setup(args.data, args.val_windows)
    t_his = ds.t_his
    cvae = dlow.cvae_model(c, ds.dim, ds.t_pred, Execution(precision=args.precision))
    params = cvae.init(jax.random.key(args.seed), jnp.zeros((1, t_his, ds.dim)), jnp.zeros((1, ds.t_pred, ds.dim)), jax.random.key(0))
    tx = adam(c.lr, args.steps, c.lr_fix_fraction)
    loss = functools.partial(dlow.cvae_loss, cvae, t_his=t_his, beta=c.beta, lambda_v=c.lambda_v)
    step = jax.jit(make_train_step(lambda p, _f, b, k: loss(p, b, k), tx), donate_argnums=0)
    recon = jax.jit(lambda p, x, y: cvae.apply(p, x, y)[0])  # no key: z = mu
    key = jax.random.key(args.seed)
    box = [create_state(params, tx)]

    def train_step(i: int, batch: np.ndarray):
        box[0], metrics = step(box[0], jnp.asarray(batch), jax.random.fold_in(key, i))
        return metrics

    def evaluate() -> float:
        return _val_error(np.asarray(recon(box[0].params, val[:, :t_his], val[:, t_his:])), val[:, t_his:])

    with CompileTimer() as compiling:  # a step on a copy (the step donates its state) and one evaluation
        warm = jax.tree.map(jnp.copy, box[0])
        jax.block_until_ready(step(warm, jnp.asarray(sampler.sample(np.random.default_rng(12345), c.batch_size)), key))
        evaluate()
    return _loop(args, train_step, evaluate, sampler, c.batch_size, compiling.seconds, jax.block_until_ready)


def torch_worker(args) -> dict:
    import torch

    from benchmarks.torch_ref import dlow as tdlow
    from jaxmotion.train.loop import lr_schedule

    _, c, sampler, val, ds = _setup(args.data, args.val_windows)
    t_his = ds.t_his
    torch.manual_seed(args.seed)
    cvae = tdlow.DLowCVAE(ds.dim, ds.t_pred, nz=c.nz, nh_rnn=c.nh_rnn, nh_mlp=tuple(c.nh_mlp))
    opt = torch.optim.Adam(cvae.parameters(), c.lr)
    sched = lr_schedule(c.lr, args.steps, c.lr_fix_fraction)  # the same schedule, step by step

    def train_step(i: int, batch: np.ndarray):
        for g in opt.param_groups:
            g["lr"] = float(sched(i - 1))
        opt.zero_grad(set_to_none=True)
        eps = torch.randn(batch.shape[0], c.nz)
        loss, _ = tdlow.cvae_loss(cvae, torch.from_numpy(batch), eps, t_his=t_his, beta=c.beta, lambda_v=c.lambda_v)
        loss.backward()
        opt.step()

    def evaluate() -> float:
        with torch.inference_mode():
            y_rec = cvae(torch.from_numpy(val[:, :t_his]), torch.from_numpy(val[:, t_his:]), None)[0]
        return _val_error(y_rec.numpy(), val[:, t_his:])

    return _loop(args, train_step, evaluate, sampler, c.batch_size, 0.0, lambda _: None)


def _loop(args, train_step, evaluate, sampler, batch_size: int, compile_s: float, sync) -> dict:
    """Runs `args.steps` steps of `train_step(i, batch)`, evaluating every `args.every`; returns the curve and clocks.

    `sync(out)` waits for a step's result (jax dispatches asynchronously): called before each
    evaluation, so the clock there covers every step so far.
    """
    rng = np.random.default_rng(args.data_seed)  # the same batches, in the same order, on both sides
    curve = [{"step": 0, "train_s": 0.0, "val": evaluate()}]
    train_s = eval_s = sample_s = 0.0
    for i in range(1, args.steps + 1):
        t0 = time.perf_counter()
        batch = sampler.sample(rng, batch_size)
        t1 = time.perf_counter()
        out = train_step(i, batch)
        last = i % args.every == 0 or i == args.steps
        if last:
            sync(out)
        train_s += time.perf_counter() - t0
        sample_s += t1 - t0
        if last:
            t2 = time.perf_counter()
            v = evaluate()
            eval_s += time.perf_counter() - t2
            curve.append({"step": i, "train_s": round(train_s, 3), "val": v})
            print(f"  step {i:5d}: {train_s:7.1f} s training, validation reconstruction {v:.4f} m", flush=True)
    return {"curve": curve, "train_s": train_s, "eval_s": eval_s, "host_sampling_s": sample_s, "compile_s": compile_s}


def first_reach(curve: list[dict], thr: float) -> float | None:
    """Returns the training seconds at the first evaluation at or below `thr` (None if never)."""
    return next((p["train_s"] for p in curve if p["val"] <= thr), None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=2000, help="training steps per framework (the config's CVAE budget)")
    ap.add_argument("--every", type=int, default=100, help="validation every N steps")
    ap.add_argument("--val-windows", type=int, default=512)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--seed", type=int, default=0, help="seed of each side's initialisation and noise draws")
    ap.add_argument("--data-seed", type=int, default=None, help="seed of the training-batch stream, the same on both sides (default: --seed)")
    ap.add_argument("--precision", choices=("float32", "bf16"), default="float32", help="jaxmotion's Config.precision")
    ap.add_argument("--worker", choices=("jax", "torch"), help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "time_to_quality.json")
    args = ap.parse_args(argv)
    args.data_seed = args.seed if args.data_seed is None else args.data_seed
    if not args.data.is_dir():
        raise SystemExit(f"time_to_quality: no Bandai-Namco-2 folder at {args.data} (see ../shared/README.md)")
    if args.worker:
        res = (jax_worker if args.worker == "jax" else torch_worker)(args)
        args.out.write_text(json.dumps(res))
        return
    import tempfile

    m = machine()
    print(f"CPU: {m['cpu']}, {m['logical_cpus']} logical CPUs; {args.steps} steps, validation every {args.every} "
          f"on {args.val_windows} windows; seed {args.seed}, batch stream {args.data_seed}")
    results, t0 = {}, time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("jax", "torch"):
            print(f"\n{name}:", flush=True)
            out = Path(tmp) / f"{name}.json"
            cmd = [sys.executable, __file__, "--worker", name, "--out", str(out), "--steps", str(args.steps),
                   "--every", str(args.every), "--val-windows", str(args.val_windows), "--data", str(args.data),
                   "--seed", str(args.seed), "--data-seed", str(args.data_seed), "--precision", args.precision]
            subprocess.run(cmd, check=True)
            results[name] = json.loads(out.read_text())
    j, t = results["jax"], results["torch"]
    print(f"\nwhole run {time.perf_counter() - t0:.0f} s. Training loop: jaxmotion {j['train_s']:.1f} s "
          f"(+ compile {j['compile_s']:.1f} s), PyTorch {t['train_s']:.1f} s; host batch sampling "
          f"{j['host_sampling_s']:.1f} / {t['host_sampling_s']:.1f} s (included)")
    rows = []
    print("threshold (m) | jaxmotion s | jaxmotion s with compile | PyTorch s | ratio (PyTorch / jaxmotion)")
    for thr in THRESHOLDS:
        a, b = first_reach(j["curve"], thr), first_reach(t["curve"], thr)
        rows.append({"threshold": thr, "jax_s": a, "jax_with_compile_s": None if a is None else a + j["compile_s"], "torch_s": b})
        ratio = f"{b / a:.2f}x" if a and b else "-"
        fmt = lambda v: "not reached" if v is None else f"{v:.1f}"  # noqa: E731
        print(f"{thr:.2f} | {fmt(a)} | {fmt(None if a is None else a + j['compile_s'])} | {fmt(b)} | {ratio}")
    both = [r for r in rows if r["jax_s"] is not None and r["torch_s"] is not None]
    headline = both[-1] if both else None
    if headline:
        print(f"headline: validation reconstruction {headline['threshold']:.2f} m reached by jaxmotion in "
              f"{headline['jax_s']:.1f} s ({headline['jax_with_compile_s']:.1f} s with compile), by PyTorch in "
              f"{headline['torch_s']:.1f} s")
    else:
        print("headline: no threshold reached by both")
    doc = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": m,
           "command": "python benchmarks/time_to_quality.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "settings": {k: str(v) for k, v in vars(args).items()}, "thresholds": rows, "headline": headline,
           "jax": j, "torch": t}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
