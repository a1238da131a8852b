"""The jaxmotion worker of the benchmark: runs every case of `harness.plan` and writes the records as JSON.

Run by `benchmarks/run.py` in its own process (`python -m benchmarks.jax_bench --settings JSON --out FILE`).
Every function is jitted once per case; tracing + XLA compilation is timed separately from the runs
(`lower(...).compile()`), and the timed runs call the compiled executable. Training steps donate
their state, as `jaxmotion.train.loop.fit` does. After its timings, each case's FLOPs are counted
(`benchmarks.flops.count`: XLA's cost analysis with the scans unrolled, and the matrix products
alone), beside XLA's figure for the compiled executable, which counts loop bodies once.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib.metadata
import json
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from benchmarks import flops
from benchmarks.harness import (DIFFUSION_NOISE_STEPS, DIFFUSION_SIZES, Case, PeakRSS, Settings, gsps_skeleton, heatmap_batch,
                               measure, parents_for, plan, reference_probe, timing)
from jaxmotion.models import diffusion, divsamp, dlow, gsps, mojo
from jaxmotion.models import motionmap as mm
from jaxmotion.nn.execution import Execution
from jaxmotion.train.loop import bn_optimizer, make_bn_train_step
from jaxmotion.train.loop import create_state, make_train_step


def _compile(fn, *args, donate=()):
    """Returns `(compiled, trace_s, compile_s)` for `jax.jit(fn)` at these arguments."""
    t0 = time.perf_counter()
    lowered = jax.jit(fn, donate_argnums=donate).lower(*args)
    t1 = time.perf_counter()
    compiled = lowered.compile()
    return compiled, t1 - t0, time.perf_counter() - t1


def _train_runner(step, state, batch):
    compiled, tr, co = _compile(step, state, batch, jax.random.key(0), donate=(0,))
    box = [jax.tree.map(jnp.array, state)]  # the step donates its state: keep the caller's arrays
    keys = [jax.random.key(i) for i in range(4)]
    i = [0]

    def run():
        i[0] += 1
        box[0], metrics = compiled(box[0], batch, keys[i[0] % 4])
        jax.block_until_ready(metrics)

    run.compiled = compiled
    run.count = lambda: flops.count(step, state, batch, jax.random.key(0))
    return run, tr, co


def _sample_runner(fn, *args):
    compiled, tr, co = _compile(fn, *args)

    def run():
        jax.block_until_ready(compiled(*args))

    run.compiled = compiled
    run.count = lambda: flops.count(fn, *args)
    return run, tr, co


class Builders:
    """Builds the `run()` closure of each case for each model (parameters from each model's own init)."""

    def __init__(self, s: Settings):
        self.s = s
        # The settings' execution choices, the one value every model receives (jaxmotion/nn/execution.py).
        self.ex = Execution(precision=s.precision, decoder_backward=s.decoder_backward, decoder_remat=s.decoder_remat,
                            decoder_unroll=s.decoder_unroll, gcn_node_major=s.gcn_node_major)
        rng = np.random.default_rng(s.seed)
        self.data = lambda b, t: jnp.asarray(rng.normal(size=(b, t, s.dim)).astype(np.float32))

    # --- DLow ------------------------------------------------------------------------------------
    def dlow(self, c: Case):
        s = self.s
        cvae = dlow.DLowCVAE(dim=s.dim, horizon=c.t_pred, execution=self.ex)
        p = cvae.init(jax.random.key(0), self.data(1, s.t_his), self.data(1, c.t_pred), jax.random.key(1))
        if c.kind == "train_cvae":
            tx = optax.adam(1e-3)
            loss = functools.partial(dlow.cvae_loss, cvae, t_his=s.t_his, beta=0.1, lambda_v=1000.0)
            step = make_train_step(lambda q, _f, b, k: loss(q, b, k), tx)
            return _train_runner(step, create_state(p, tx), self.data(c.batch, s.t_his + c.t_pred))
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            return _sample_runner(lambda p, x, key: dlow.sample_prior(cvae, p, x, key, c.k), p, x, jax.random.key(2))
        q = dlow.DLowQ(nk=c.k, execution=self.ex)
        qp = q.init(jax.random.key(3), x[:1], jnp.zeros((1, cvae.nz)))
        if c.kind == "sample":
            return _sample_runner(lambda p, qp, x, key: dlow.sample_dlow(cvae, p, q, qp, x, key), p, qp, x, jax.random.key(2))
        tx = optax.adam(1e-4)
        loss = functools.partial(dlow.dlow_loss, q, cvae=cvae, t_his=s.t_his, d_scale=100.0, lambda_j=25.0,
                                 lambda_recon=2.0, lambda_kl=1.0)
        step = make_train_step(lambda qp, f, b, k: loss(qp, cvae_params=f, batch=b, key=k), tx)
        return _train_runner(step, create_state(qp, tx, frozen=p), self.data(c.batch, s.t_his + c.t_pred))

    # --- MOJO ------------------------------------------------------------------------------------
    def mojo(self, c: Case):
        s = self.s
        cfg = mojo.MojoConfig()
        model = mojo.cvae_model(cfg, s.dim, c.t_pred, self.ex)
        p = model.init(jax.random.key(0), self.data(1, s.t_his), self.data(1, c.t_pred), jax.random.key(1))
        if c.kind == "train_cvae":
            tx = optax.adam(cfg.lr)
            loss = functools.partial(mojo.cvae_loss, model, t_his=s.t_his, **mojo.cvae_loss_weights(cfg))
            step = make_train_step(lambda q, _f, b, k: loss(q, b, k), tx)
            return _train_runner(step, create_state(p, tx), self.data(c.batch, s.t_his + c.t_pred))
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            return _sample_runner(lambda p, x, key: mojo.sample_prior(model, p, x, key, c.k), p, x, jax.random.key(2))
        q = mojo.q_model(cfg, c.t_pred, c.k, self.ex)
        qp = q.init(jax.random.key(3), x[:1], jnp.zeros((1, q.n_low, cfg.nz)))
        if c.kind == "sample":
            return _sample_runner(lambda p, qp, x, key: mojo.sample_mojo(model, p, q, qp, x, key), p, qp, x, jax.random.key(2))
        tx = optax.adam(cfg.q_lr)
        loss = functools.partial(mojo.q_loss, q, model=model, t_his=s.t_his, **mojo.q_loss_weights(cfg))
        step = make_train_step(lambda qp, f, b, k: loss(qp, cvae_params=f, batch=b, key=k), tx)
        return _train_runner(step, create_state(qp, tx, frozen=p), self.data(c.batch, s.t_his + c.t_pred))

    # --- DivSamp ---------------------------------------------------------------------------------
    def divsamp(self, c: Case):
        s = self.s
        d = divsamp.DivSampConfig()
        cvae = divsamp.cvae_from_config(d, self.ex)
        cx0 = jnp.zeros((2, s.dim // 3, 3 * d.n_dct))
        v = dict(cvae.init(jax.random.key(0), cx0, cx0, jax.random.key(1), train=False))
        if c.kind == "train_cvae":
            tx = bn_optimizer(optax.chain(optax.clip_by_global_norm(d.cvae_grad_clip), optax.adam(d.cvae_lr)))
            loss = functools.partial(divsamp.cvae_loss, cvae, t_his=s.t_his, parents=parents_for(s.dim), beta=d.beta,
                                     lambda_v=d.lambda_v, lambda_his=d.lambda_his, lambda_limb=d.lambda_limb)
            step = make_bn_train_step(lambda q, _f, b, k: loss(q, b, k), tx)
            return _train_runner(step, create_state(v, tx), self.data(c.batch, s.t_his + c.t_pred))
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            fn = lambda v, x, key: divsamp.sample_prior(cvae, v, x, key, c.k, t_pred=c.t_pred)
            return _sample_runner(fn, v, x, jax.random.key(2))
        sampler = divsamp.sampler_from_config(d, self.ex)
        sv = dict(sampler.init(jax.random.key(3), cx0, jax.random.key(4), 2, train=False))
        if c.kind == "sample":
            fn = lambda v, sv, x, key: divsamp.sample_divsamp(cvae, v, sampler, sv, x, key, c.k, t_pred=c.t_pred)
            return _sample_runner(fn, v, sv, x, jax.random.key(2))
        tx = bn_optimizer(optax.adam(d.lr))
        loss = functools.partial(divsamp.sampler_loss, sampler, cvae=cvae, t_his=s.t_his, k=c.k, lambda_kl=d.lambda_kl,
                                 lambda_acc=d.lambda_acc, lambda_div=d.lambda_div, eta=d.eta)
        step = make_bn_train_step(lambda q, f, b, k: loss(q, cvae_variables=f, batch=b, key=k), tx)
        return _train_runner(step, create_state(sv, tx, frozen=v), self.data(c.batch, s.t_his + c.t_pred))


    # --- GSPS ------------------------------------------------------------------------------------
    def gsps(self, c: Case):
        s, g = self.s, gsps.GSPSConfig()
        parents, roles, parts, bounds = gsps_skeleton(s.dim)
        gen = gsps.GSPSGenerator(parts=parts, hidden=g.hidden, num_stage=g.num_stage, execution=self.ex)
        nodes0 = jnp.zeros((2, s.dim // 3, 3 * g.n_pre))
        v = dict(gen.init(jax.random.key(0), nodes0, jnp.zeros((2, len(parts), g.nz)), train=False))
        if c.kind == "train_generator":
            nk1, nk2 = s.gsps_nk
            prior = gsps.PosePrior(dim=s.dim, n_layers=g.prior_layers)
            frozen = {"prior": prior.init(jax.random.key(1), jnp.zeros((1, s.dim))), "bounds": jnp.asarray(bounds)}
            weights = {k: getattr(g, k) for k in (
                "lambda_his", "lambda_limb", "lambda_div_first", "lambda_div_rest", "alpha", "beta", "lambda_recon",
                "lambda_recon_mm", "lambda_prior", "prior_stride", "lambda_angle")}
            loss = functools.partial(gsps.generator_loss, gen, prior=prior, t_his=s.t_his, parents=parents, parts=parts,
                                     roles=roles, n_pre=g.n_pre, nz=g.nz, nk1=nk1, nk2=nk2, best_of=s.gsps_best_of,
                                     **weights)
            tx = bn_optimizer(optax.chain(optax.clip_by_global_norm(g.grad_clip), optax.adam(g.lr)))
            step = make_bn_train_step(
                lambda v, f, b, k: loss(v, prior_params=f["prior"], angle_bounds=f["bounds"], batch=b, key=k), tx)
            batch = {"window": self.data(c.batch, s.t_his + c.t_pred),
                     "mm": self.data(c.batch * s.gsps_mm, c.t_pred).reshape(c.batch, s.gsps_mm, c.t_pred, s.dim),
                     "mm_mask": jnp.ones((c.batch, s.gsps_mm))}
            return _train_runner(step, create_state(v, tx, frozen=frozen), batch)
        x = self.data(c.batch, s.t_his)

        def sample(v, x, key):
            z = gsps.sample_noise(key, c.batch, c.k, len(parts), g.nz)
            return gsps.generate(gen, v, x, z, t_pred=c.t_pred, n_pre=g.n_pre, train=False)[0][:, :, s.t_his :]

        return _sample_runner(sample, v, x, jax.random.key(2))

    # --- MotionMap -------------------------------------------------------------------------------
    def motionmap(self, c: Case):
        s = self.s
        m = mm.MotionMapConfig(hm_size=s.hm_size)
        if c.kind == "train_ae":
            ae = mm.ae_model(m, s.dim, s.t_his, c.t_pred)
            p = ae.init(jax.random.key(0), self.data(1, s.t_his), self.data(1, c.t_pred))
            tx = optax.amsgrad(m.lr)  # the release's Adam(amsgrad=True)
            step = make_train_step(lambda q, _f, b, k: mm.ae_loss(ae, q, b, scale=m.loss_scale), tx)
            batch = {"x": self.data(c.batch, s.t_his), "y": self.data(c.batch, c.t_pred)}
            return _train_runner(step, create_state(p, tx), batch)
        hm = mm.heatmap_model(m)
        x = self.data(c.batch, s.t_his)
        p = hm.init(jax.random.key(1), x[:1])
        if c.kind == "train_heatmap":
            cells, batch = heatmap_batch(s, c)
            tx = optax.amsgrad(m.lr)
            step = make_train_step(lambda q, _f, b, k: mm.heatmap_loss(
                hm, q, jnp.asarray(cells), b, size=s.hm_size, sigma=m.hm_sigma, pos_weight=m.pos_weight), tx)
            batch = {"x": x, **{k: jnp.asarray(v) for k, v in batch.items()}}
            return _train_runner(step, create_state(p, tx), batch)
        return _sample_runner(lambda p, x: jax.nn.sigmoid(hm.apply(p, x)), p, x)


    # --- Diffusion -------------------------------------------------------------------------------
    def diffusion(self, c: Case):
        s = self.s
        model = diffusion.Denoiser(dim=s.dim, execution=self.ex, **DIFFUSION_SIZES)
        x0 = jnp.zeros((1, model.n_dct, s.dim))
        p = model.init(jax.random.key(0), x0, jnp.ones((1,), jnp.int32), x0, jnp.ones((1,)))
        abar = diffusion.schedule("cosine", DIFFUSION_NOISE_STEPS)
        devices = None
        if s.jax_host_devices > 1:
            if jax.local_device_count() < s.jax_host_devices:
                raise RuntimeError(f"jax_host_devices = {s.jax_host_devices}, but jax has {jax.local_device_count()} local "
                                   "device(s): run.py sets XLA_FLAGS for the jax worker")
            devices = jax.local_devices()[:s.jax_host_devices]
        fn = lambda p, x, key, devices=devices: diffusion.sample(model, p, x, key, c.k, t_pred=c.t_pred, abar=abar,
                                                                 sampling_steps=c.steps, devices=devices)
        args = (p, self.data(c.batch, s.t_his), jax.random.key(2))
        run, tr, co = _sample_runner(fn, *args)
        # The FLOPs of the whole sampler: the cost analysis of a program split over devices counts one device's share.
        run.count = lambda: flops.count(functools.partial(fn, devices=None), *args)
        return run, tr, co


def matmul_probe(n: int):
    """Returns a call that runs one fixed n x n float32 product in jax (`harness.measure`'s machine-speed gate), or None for n = 0."""
    if not n:
        return None
    a = jax.random.normal(jax.random.key(0), (n, n), jnp.float32)
    f = jax.jit(lambda a: a @ a)
    return lambda: f(a).block_until_ready()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--settings", required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    s = Settings.from_dict(json.loads(args.settings))
    mem = PeakRSS()
    builders = Builders(s)
    records = []
    probe = matmul_probe(s.probe_n)
    ref = reference_probe(probe)
    for c in plan(s):
        rss0 = mem.reset()
        t0 = time.perf_counter()
        run, trace_s, compile_s = getattr(builders, c.model)(c)
        rec = dict(dataclasses.asdict(c), case=c.name, framework="jax", trace_s=trace_s, compile_s=compile_s)
        rec.update(measure(run, *timing(s, c), probe, ref, s.slow_factor, s.probe_min_call_s))
        rec.update(rss_before_mb=rss0, peak_rss_mb=mem.peak_mb(), wall_s=time.perf_counter() - t0)
        # After the timings and the memory peak: counting lowers the case once more, with its loops unrolled.
        rec.update(run.count(), xla_compiled_flops=float(run.compiled.cost_analysis()["flops"]))
        if c.model == "dlow" and c.kind == "sample_prior":  # the case run.py checks the count on
            rec["hand_matmul_flops"] = flops.dlow_prior_hand_count(dlow.DLowCVAE(dim=s.dim, horizon=c.t_pred), s.t_his, c.k)
        records.append(rec)
        print(f"jax {c.name}: {rec['median_s'] * 1e3:.2f} ms (compile {compile_s:.1f} s), {rec['flops'] / 1e9:.3g} GFLOP",
              flush=True)
        del run
        jax.clear_caches()
    info = {"framework": "jax", "versions": {"jax": jax.__version__, "jaxlib": importlib.metadata.version("jaxlib"),
                                             "flax": __import__("flax").__version__, "optax": optax.__version__},
            "devices": [str(d) for d in jax.devices()], "peak_rss_resettable": mem.resettable}
    with open(args.out, "w") as f:
        json.dump({"info": info, "records": records}, f, indent=1)


if __name__ == "__main__":
    main()
