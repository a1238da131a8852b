"""The PyTorch worker of the benchmark: runs every case of `harness.plan` eagerly or under `torch.compile`.

Run by `benchmarks/run.py` in its own process
(`python -m benchmarks.torch_ref.bench --settings JSON --out FILE [--compile]`). Training steps are
`zero_grad; loss.backward(); optimiser.step()`; sampling runs under `torch.inference_mode()`.
With `--compile`, the loss function (forward; AOTAutograd compiles its backward) and the sampler
are wrapped in `torch.compile` (default inductor backend); the first call, which compiles, is
timed as `compile_s` and excluded from the measurements like every warm-up call.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from benchmarks.harness import (DIFFUSION_NOISE_STEPS, DIFFUSION_SIZES, Case, PeakRSS, Settings, gsps_skeleton, heatmap_batch,
                               measure, parents_for, plan, reference_probe, timing)
from benchmarks.torch_ref import diffusion, divsamp, dlow, gsps, mojo, motionmap


class Builders:
    def __init__(self, s: Settings, compile_: bool):
        self.s, self.compile = s, compile_
        rng = np.random.default_rng(s.seed)
        self.data = lambda b, t: torch.from_numpy(rng.normal(size=(b, t, s.dim)).astype(np.float32))
        self.compile_s = float("nan")

    def _wrap(self, fn):
        return torch.compile(fn) if self.compile else fn

    def _train(self, loss_fn, params, opt, clip: float | None = None):
        loss_fn = self._wrap(loss_fn)

        def run():
            opt.zero_grad(set_to_none=True)
            loss, _ = loss_fn()
            loss.backward()
            if clip is not None:
                torch.nn.utils.clip_grad_norm_(params, clip)
            opt.step()

        return self._first(run)

    def _sample(self, fn):
        fn = self._wrap(fn)

        def run():
            with torch.inference_mode():
                return fn()

        return self._first(run)

    def _first(self, run):
        """Calls `run` once (under torch.compile, this compiles) and returns it."""
        t0 = time.perf_counter()
        run()
        self.compile_s = time.perf_counter() - t0 if self.compile else float("nan")
        return run

    # --- DLow ------------------------------------------------------------------------------------
    def dlow(self, c: Case):
        s = self.s
        cvae = dlow.DLowCVAE(s.dim, c.t_pred)
        if c.kind == "train_cvae":
            batch = self.data(c.batch, s.t_his + c.t_pred)
            loss = lambda: dlow.cvae_loss(cvae, batch, torch.randn(c.batch, cvae.nz), t_his=s.t_his, beta=0.1, lambda_v=1000.0)
            return self._train(loss, list(cvae.parameters()), torch.optim.Adam(cvae.parameters(), 1e-3))
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            return self._sample(lambda: dlow.sample_prior(cvae, x, torch.randn(c.batch, c.k, cvae.nz)))
        q = dlow.DLowQ(s.dim, nk=c.k)
        if c.kind == "sample":
            return self._sample(lambda: dlow.sample_dlow(cvae, q, x, torch.randn(c.batch, cvae.nz)))
        cvae.requires_grad_(False)  # the frozen decoder
        batch = self.data(c.batch, s.t_his + c.t_pred)
        loss = lambda: dlow.dlow_loss(q, cvae, batch, torch.randn(c.batch, cvae.nz), t_his=s.t_his, d_scale=100.0,
                                      lambda_j=25.0, lambda_recon=2.0, lambda_kl=1.0)
        return self._train(loss, list(q.parameters()), torch.optim.Adam(q.parameters(), 1e-4))

    # --- MOJO ------------------------------------------------------------------------------------
    def mojo(self, c: Case):
        s = self.s
        model = mojo.MojoCVAE(s.dim, c.t_pred)
        if c.kind == "train_cvae":
            batch = self.data(c.batch, s.t_his + c.t_pred)
            loss = lambda: mojo.cvae_loss(model, batch, torch.randn(c.batch, model.n_bands, model.nz), t_his=s.t_his)
            return self._train(loss, list(model.parameters()), torch.optim.Adam(model.parameters(), 1e-3))
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            return self._sample(lambda: mojo.decode_k(model, x, torch.randn(c.batch, c.k, model.n_bands, model.nz)))
        n_low = max(1, round(0.2 * model.n_bands))
        q = mojo.MojoQ(s.dim, model.nz, c.k, n_low)
        draws = lambda: (torch.randn(c.batch, n_low, model.nz), torch.randn(c.batch, c.k, model.n_bands - n_low, model.nz))
        if c.kind == "sample":
            return self._sample(lambda: mojo.sample_mojo(model, q, x, *draws()))
        model.requires_grad_(False)
        batch = self.data(c.batch, s.t_his + c.t_pred)
        loss = lambda: mojo.q_loss(q, model, batch, *draws(), t_his=s.t_his)
        return self._train(loss, list(q.parameters()), torch.optim.Adam(q.parameters(), 1e-4))

    # --- DivSamp ---------------------------------------------------------------------------------
    def divsamp(self, c: Case):
        s = self.s
        j = s.dim // 3
        cvae = divsamp.DivSampCVAE(j)
        if c.kind == "train_cvae":
            batch = self.data(c.batch, s.t_his + c.t_pred)
            parents = parents_for(s.dim)
            loss = lambda: divsamp.cvae_loss(cvae, batch, torch.randn(c.batch, cvae.nz), t_his=s.t_his, parents=parents)
            return self._train(loss, list(cvae.parameters()), torch.optim.Adam(cvae.parameters(), 1e-3), clip=100.0)
        cvae.eval()  # the decoder samples with BatchNorm running averages
        x = self.data(c.batch, s.t_his)
        if c.kind == "sample_prior":
            def prior():
                cx = divsamp.condition_nodes(x, c.t_pred, cvae.n_dct)
                return divsamp.decode_k(cvae, cx, torch.randn(c.batch, c.k, cvae.nz), t_his=s.t_his, t_pred=c.t_pred)
            return self._sample(prior)
        sampler = divsamp.DivSampSampler(j)
        draws = lambda: (divsamp.gumbel_coefficients(c.batch, c.k, sampler.num_bases), torch.randn(c.batch, 1, sampler.nz))
        if c.kind == "sample":
            sampler.eval()
            return self._sample(lambda: divsamp.sample_divsamp(cvae, sampler, x, *draws(), t_pred=c.t_pred))
        cvae.requires_grad_(False)
        batch = self.data(c.batch, s.t_his + c.t_pred)
        loss = lambda: divsamp.sampler_loss(sampler, cvae, batch, *draws(), t_his=s.t_his)
        return self._train(loss, list(sampler.parameters()), torch.optim.Adam(sampler.parameters(), 1e-3))


    # --- GSPS ------------------------------------------------------------------------------------
    def gsps(self, c: Case):
        s = self.s
        parents, roles, parts, bounds = gsps_skeleton(s.dim)
        gen = gsps.GSPSGenerator(s.dim // 3, parts)
        if c.kind == "train_generator":
            nk1, nk2 = s.gsps_nk
            prior = gsps.PosePrior(s.dim).requires_grad_(False)  # trained first, then frozen
            batch = {"window": self.data(c.batch, s.t_his + c.t_pred),
                     "mm": self.data(c.batch * s.gsps_mm, c.t_pred).reshape(c.batch, s.gsps_mm, c.t_pred, s.dim),
                     "mm_mask": torch.ones(c.batch, s.gsps_mm)}
            kw = dict(t_his=s.t_his, parents=parents, parts=parts, roles=roles, angle_bounds=torch.tensor(bounds),
                      nk1=nk1, nk2=nk2, **gsps.loss_weights())
            loss = lambda: gsps.generator_loss(gen, prior, batch, gsps.training_noise(c.batch, len(parts), nk1, nk2, gen.nz),
                                               int(torch.randint(kw["prior_stride"], ())), **kw)
            return self._train(loss, list(gen.parameters()), torch.optim.Adam(gen.parameters(), 1e-3), clip=100.0)
        gen.eval()  # sampling uses the BatchNorm running averages
        x = self.data(c.batch, s.t_his)
        return self._sample(lambda: gsps.sample_gsps(gen, x, gsps.sample_noise(c.batch, c.k, len(parts), gen.nz),
                                                     t_pred=c.t_pred))

    # --- MotionMap -------------------------------------------------------------------------------
    def motionmap(self, c: Case):
        s = self.s
        if c.kind == "train_ae":
            ae = motionmap.MotionMapAE(s.dim, s.t_his, c.t_pred)
            batch = {"x": self.data(c.batch, s.t_his), "y": self.data(c.batch, c.t_pred)}
            loss = lambda: motionmap.ae_loss(ae, batch, scale=10.0)
            return self._train(loss, list(ae.parameters()), torch.optim.Adam(ae.parameters(), 1e-3, amsgrad=True))
        hm = motionmap.HeatmapNet(s.dim, s.hm_size)
        x = self.data(c.batch, s.t_his)
        if c.kind == "train_heatmap":
            cells, batch = heatmap_batch(s, c)
            cells, batch = torch.from_numpy(cells), {"x": x, **{k: torch.from_numpy(v) for k, v in batch.items()}}
            loss = lambda: motionmap.heatmap_loss(hm, cells, batch, size=s.hm_size, sigma=8.0**0.5, pos_weight=10.0)
            return self._train(loss, list(hm.parameters()), torch.optim.Adam(hm.parameters(), 1e-3, amsgrad=True))
        return self._sample(lambda: torch.sigmoid(hm(x)))


    # --- Diffusion -------------------------------------------------------------------------------
    def diffusion(self, c: Case):
        s = self.s
        model = diffusion.Denoiser(s.dim, **DIFFUSION_SIZES).eval()  # eval: dropout off, as at test time
        abar, t_seq, t_prev = diffusion.ddim_schedule(DIFFUSION_NOISE_STEPS, c.steps)
        mask = diffusion.completion_mask(s.t_his + c.t_pred, s.dim, s.t_his)
        x = self.data(c.batch, s.t_his)
        return self._sample(lambda: diffusion.sample_ddim(model, x, c.k, t_pred=c.t_pred, n_dct=model.n_dct, abar=abar,
                                                          t_seq=t_seq, t_prev=t_prev, mask=mask))


def matmul_probe(n: int):
    """Returns a call that runs one fixed n x n float32 product in PyTorch (`harness.measure`'s machine-speed gate), or None for n = 0."""
    if not n:
        return None
    a = torch.randn(n, n, generator=torch.Generator().manual_seed(0))
    return lambda: torch.mm(a, a)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--settings", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--compile", action="store_true", help="wrap losses and samplers in torch.compile")
    ap.add_argument("--cases", default="", help="comma-separated case kinds to run (default: all)")
    args = ap.parse_args()
    s = Settings.from_dict(json.loads(args.settings))
    kinds = set(filter(None, args.cases.split(",")))
    fw = "torch_compile" if args.compile else "torch_eager"
    torch.manual_seed(s.seed)
    mem = PeakRSS()
    builders = Builders(s, args.compile)
    records = []
    probe = matmul_probe(s.probe_n)
    ref = reference_probe(probe)
    for c in plan(s):
        if kinds and c.kind not in kinds:
            continue
        rss0 = mem.reset()
        t0 = time.perf_counter()
        rec = dict(dataclasses.asdict(c), case=c.name, framework=fw)
        try:
            run = getattr(builders, c.model)(c)
        except Exception as e:  # torch.compile can fail on a machine (no compiler, unsupported op): record it
            if not args.compile:
                raise
            rec.update(error=f"{type(e).__name__}: {str(e).splitlines()[0][:300]}")
            records.append(rec)
            print(f"{fw} {c.name}: FAILED {rec['error']}", flush=True)
            continue
        rec["compile_s"] = builders.compile_s
        rec.update(measure(run, *timing(s, c), probe, ref, s.slow_factor, s.probe_min_call_s))
        rec.update(rss_before_mb=rss0, peak_rss_mb=mem.peak_mb(), wall_s=time.perf_counter() - t0)
        records.append(rec)
        print(f"{fw} {c.name}: {rec['median_s'] * 1e3:.2f} ms", flush=True)
        del run
        if args.compile:
            torch._dynamo.reset()
    info = {"framework": fw, "versions": {"torch": torch.__version__}, "threads": torch.get_num_threads(),
            "mkldnn": torch.backends.mkldnn.is_available(), "peak_rss_resettable": mem.resettable}
    with open(args.out, "w") as f:
        json.dump({"info": info, "records": records}, f, indent=1)


if __name__ == "__main__":
    main()
