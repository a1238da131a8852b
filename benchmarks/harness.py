"""What the benchmark measures and how: the settings, the list of cases, timing and peak memory.

Shared by the parent (`run.py`) and the two workers (`jax_bench.py`, `torch_ref/bench.py`), so both
frameworks run exactly the same cases with the same sizes, warm-up and repeat counts.
"""

from __future__ import annotations

import dataclasses
import gc
import os
import platform
import resource
import statistics
import time
from typing import Callable

import numpy as np

MODELS = ("dlow", "mojo", "divsamp", "gsps", "motionmap", "diffusion")
# The diffusion predictor's denoiser in the benchmark: `DiffusionConfig`'s defaults (sized for Bandai-Namco-2
# on a CPU; tests/test_torch_parity_diffusion.py checks they agree), 1000 noise steps on the cosine schedule.
DIFFUSION_SIZES = dict(n_dct=15, latent=64, ff=128, num_layers=4, num_heads=4)
DIFFUSION_NOISE_STEPS = 1000


@dataclasses.dataclass
class Settings:
    """Sizes (Bandai-Namco-2's protocol: D = 60, 15 -> 60 frames at 30 fps) and repeat counts."""

    dim: int = 60
    t_his: int = 15
    t_pred: int = 60
    train_batch: int = 64  # first stage (the CVAE), windows per step
    sampler_batch: int = 16  # second stage (sampler on the frozen decoder): the shared budget's batch 16 x K 50
    k: int = 50
    sample_batches: tuple[int, ...] = (1, 64)
    k_sweep: tuple[int, ...] = (1, 10, 50, 100, 500, 1000)
    t_pred_sweep: tuple[int, ...] = (15, 30, 60, 120)
    gsps_nk: tuple[int, int] = (10, 10)  # GSPS training samples per window, nk1 x nk2 (the release's)
    gsps_mm: int = 10  # pseudo ground-truth futures per window in GSPS's training step (the release's)
    hm_size: int = 128  # MotionMap's heatmap side (the release's 128 x 128)
    hm_members: int = 64  # MotionMap's heatmap stage: multimodal futures drawn into each target map (MotionMapConfig.max_members)
    peak_sizes: tuple[int, ...] = (1024, 2048, 4096)  # n x n products that measure the machine's peak (peak.py)
    warmup: int = 2
    repeats: int = 7
    # The machine-speed probe of `measure`: a fixed n x n product of the worker's own framework after each
    # call of a case whose call takes at least probe_min_call_s, recorded with the case; probe_n = 0: none.
    # slow_factor > 1 also leaves out calls whose probe was that much slower than the fastest (the gate;
    # off by default: benchmarks/results/machine.md says where it misfires).
    probe_n: int = 768
    slow_factor: float = 0.0
    probe_min_call_s: float = 0.02
    models: tuple[str, ...] = MODELS
    seed: int = 0
    precision: str = "float32"  # jaxmotion's products (Config.precision); the PyTorch twins stay float32
    # jaxmotion's execution choices (jaxmotion/nn/execution.py `Execution`, which jax_bench.py builds from these):
    decoder_remat: bool = True  # Execution.decoder_remat: DLow's and MOJO's CVAE decoders (benchmarks/ab.py --ab decoder_remat)
    decoder_unroll: int = 1  # Execution.decoder_unroll of the same (benchmarks/ab.py --ab decoder_unroll)
    decoder_backward: str = "batched"  # Execution.decoder_backward of the same (benchmarks/ab.py --ab decoder_backward)
    gcn_node_major: bool = True  # Execution.gcn_node_major: the GCL stacks' layout in DivSamp and GSPS (benchmarks/ab.py --ab gcn_node_major)
    gsps_best_of: str = "gram"  # how GSPS's loss forms its best-of-K errors (generator_loss best_of; ab.py --ab gsps_best_of)
    ddim_steps: tuple[int, ...] = (100, 10)  # the diffusion predictor's DDIM steps, each timed at every sampling batch
    ddim_warmup: int = 1  # the diffusion cases' own warm-up and repeat counts: one K = 50 batch of 64 at 100 steps
    ddim_repeats: int = 3  # is tens of seconds per call in PyTorch on a 2-core CPU
    # CPU host devices of the jax worker (`--xla_force_host_platform_device_count`); above 1 the diffusion
    # sampler splits its K samples over them (`diffusion.sample(devices=...)`), every other case runs on one.
    jax_host_devices: int = 1

    @classmethod
    def from_dict(cls, d: dict) -> "Settings":
        """Returns the settings `dataclasses.asdict` gave, after a JSON round trip (lists back to tuples); an unknown field is an error."""
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    @classmethod
    def from_record(cls, d: dict) -> "Settings":
        """Returns the settings a results file recorded; a knob since removed (a field not here) is ignored."""
        known = {f.name for f in dataclasses.fields(cls)}
        return cls.from_dict({k: v for k, v in d.items() if k in known})

    @classmethod
    def quick(cls, **kw) -> "Settings":
        """Returns tiny settings for a smoke test (seconds, not minutes; numbers not meaningful)."""
        base = dict(train_batch=8, sampler_batch=2, k=5, sample_batches=(1, 4), k_sweep=(1, 20), t_pred_sweep=(10, 30),
                    t_pred=30, warmup=1, repeats=2, probe_n=256, ddim_steps=(10, 5), ddim_repeats=2, gsps_nk=(2, 2), gsps_mm=3, hm_size=16, hm_members=4, peak_sizes=(256, 512))
        base.update(kw)
        return cls(**base)


@dataclasses.dataclass(frozen=True)
class Case:
    """One measurement: `kind` is train_cvae | train_sampler | sample | sample_prior (DLow, MOJO, DivSamp);
    train_generator | sample (GSPS); train_ae | heatmap (MotionMap)."""

    model: str
    kind: str
    batch: int
    k: int = 0
    t_pred: int = 0
    steps: int = 0  # sampling steps (the diffusion predictor's DDIM)

    @property
    def name(self) -> str:
        parts = [self.model, self.kind, f"b{self.batch}"]
        if self.k:
            parts.append(f"k{self.k}")
        if self.t_pred:
            parts.append(f"t{self.t_pred}")
        if self.steps:
            parts.append(f"s{self.steps}")
        return "/".join(parts)


def timing(s: "Settings", c: Case) -> tuple[int, int]:
    """Returns `(warmup, repeats)` for case `c`: the diffusion sampler's own counts, every other case's `s.warmup, s.repeats`."""
    return (s.ddim_warmup, s.ddim_repeats) if c.kind == "sample_ddim" else (s.warmup, s.repeats)


def plan(s: Settings) -> list[Case]:
    """Returns every case of a run, in the order both workers run them.

    The sweeps decode latents drawn from N(0, I) with the CVAE decoder (the part whose cost grows
    with K and t_pred; DLow's and MOJO's Q networks are trained for one K). GSPS has one network to
    train after its (cheap, single-frame) pose prior: its generator step draws nk1 x nk2 samples per
    window (`k` = nk1 * nk2) at the second stages' batch; MotionMap's autoencoder step runs at the
    first stages' batch, as does its heatmap stage's step (`k` = the multimodal futures drawn into each
    target map; the targets are built inside the step from a pool of map cells, as in training), and
    its heatmap network's forward pass (the map of every window, sigmoid included) at the sampling batches.
    The diffusion predictor is timed sampling K futures (DDIM with DCT completion) at each of `ddim_steps`
    and each sampling batch.
    """
    cases = []
    for m in s.models:
        if m == "gsps":
            cases.append(Case(m, "train_generator", s.sampler_batch, k=s.gsps_nk[0] * s.gsps_nk[1], t_pred=s.t_pred))
            cases += [Case(m, "sample", b, k=s.k, t_pred=s.t_pred) for b in s.sample_batches]
            continue
        if m == "diffusion":
            cases += [Case(m, "sample_ddim", b, k=s.k, t_pred=s.t_pred, steps=n) for n in s.ddim_steps for b in s.sample_batches]
            continue
        if m == "motionmap":
            cases.append(Case(m, "train_ae", s.train_batch, t_pred=s.t_pred))
            cases.append(Case(m, "train_heatmap", s.train_batch, k=s.hm_members))
            cases += [Case(m, "heatmap", b) for b in s.sample_batches]
            continue
        cases.append(Case(m, "train_cvae", s.train_batch, t_pred=s.t_pred))
        cases.append(Case(m, "train_sampler", s.sampler_batch, k=s.k, t_pred=s.t_pred))
        cases += [Case(m, "sample", b, k=s.k, t_pred=s.t_pred) for b in s.sample_batches]
        cases += [Case(m, "sample_prior", 1, k=k, t_pred=s.t_pred) for k in s.k_sweep]
        cases += [Case(m, "sample_prior", 1, k=s.k, t_pred=t) for t in s.t_pred_sweep if t != s.t_pred]
    return cases


def windows_per_step(case: Case) -> int:
    return case.batch


# ---------------------------------------------------------------------------------------------
# Timing and memory.


def summarise(times: list[float]) -> dict:
    """Returns the median and spread (quartiles, min, max) of `times` in seconds."""
    q = statistics.quantiles(times, n=4, method="inclusive") if len(times) > 1 else [times[0]] * 3
    return {"median_s": statistics.median(times), "p25_s": q[0], "p75_s": q[2], "min_s": min(times),
            "max_s": max(times), "n": len(times)}


def _timed(f: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0


def probe_time(probe: Callable[[], object]) -> float:
    """Returns the time of the second of two back-to-back `probe()` calls (the first warms caches and threads)."""
    probe()
    return _timed(probe)


def reference_probe(probe: Callable[[], object] | None, n: int = 10) -> float | None:
    """Returns the fastest of `n` probe times (a worker's reference speed of the machine, taken at its start)."""
    return min(probe_time(probe) for _ in range(n)) if probe is not None else None


def measure(run: Callable[[], object], warmup: int, repeats: int, probe: Callable[[], object] | None = None,
            ref_s: float | None = None, slow_factor: float = 0.0, probe_min_call_s: float = 0.02,
            max_calls_factor: int = 3) -> dict:
    """Returns `summarise` of `repeats` wall-clock timings of `run()` after `warmup` untimed calls.

    `run` must return only when the work is done (JAX: `block_until_ready`).

    With `probe` (a fixed matrix product in the worker's own framework, `matmul_probe`), and where the
    last warm-up call took at least `probe_min_call_s`, each timed call is followed by a probe
    (`probe_time`) and the record also holds `calls`, `slow_calls` and the probe's fastest and median
    ms (the fastest over `ref_s`, the worker's reference taken at its start, and every probe since),
    so a reader can see whether the machine ran at full speed during the case. On the 2-core cloud
    CPU this benchmark runs on, the same 768^3 product took 2.1 ms in one jax worker and 4.0 ms in
    another, and a 1024^3 product doubled its time for stretches of 10-50 calls within one process
    (benchmarks/results/machine.md). With `slow_factor` > 1, a call whose
    probe took more than `slow_factor` times the fastest is not counted, and calls continue until
    `repeats` are counted or `max_calls_factor * repeats` were made. Short calls are not probed one by
    one (the probe would evict their data from the caches and take longer than the call): the case is
    bracketed instead, one probe before its warm-up calls and one after its timed calls, and the record
    holds `bracket_probe_ms` (the two) and the same `probe_ms_min` / `probe_ms_median`, so a short
    case's figures also say how fast the machine ran around them. No call is left out by the gate.
    """
    before = probe_time(probe) if probe is not None else None
    last = 0.0
    for _ in range(warmup):
        last = _timed(run)
    if probe is None or last < probe_min_call_s:
        out = summarise([_timed(run) for _ in range(repeats)])
        if probe is not None:
            after = probe_time(probe)
            out.update(bracket_probe_ms=[before * 1e3, after * 1e3],
                       probe_ms_min=min([before, after] + ([ref_s] if ref_s else [])) * 1e3,
                       probe_ms_median=statistics.median([before, after]) * 1e3)
        return out
    best = min([before] + [probe_time(probe) for _ in range(2)])
    best = min(best, ref_s) if ref_s else best
    calls: list[tuple[float, float]] = []
    while True:
        t = _timed(run)
        p = probe_time(probe)
        calls.append((t, p))
        best = min(best, p)
        kept = [t for t, p in calls if slow_factor <= 1 or p <= slow_factor * best]
        if len(kept) >= repeats or len(calls) >= max_calls_factor * repeats:
            break
    if not kept:  # every probe after a call was slow: keep the call with the fastest probe
        kept = [min(calls, key=lambda c: c[1])[0]]
    out = summarise(kept)
    out.update(calls=len(calls), slow_calls=len(calls) - len(kept), probe_ms_min=best * 1e3,
               probe_ms_median=statistics.median(p for _, p in calls) * 1e3)
    return out


def _status_kb(field: str) -> float | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return float(line.split()[1])
    except OSError:
        pass
    return None


class PeakRSS:
    """The process's resident-set high-water mark, reset per case on Linux.

    Writing "5" to /proc/self/clear_refs resets VmHWM to the current RSS (Linux >= 4.0), so the
    peak read after a case is the peak during it (its set-up included). Elsewhere the process's
    lifetime maximum (`ru_maxrss`) is reported instead and `resettable` is False.
    """

    def __init__(self):
        self.resettable = False
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
            self.resettable = _status_kb("VmHWM") is not None
        except OSError:
            pass

    def reset(self) -> float:
        """Returns the current RSS in MB after resetting the high-water mark."""
        gc.collect()
        if self.resettable:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")
        return self.current_mb()

    def current_mb(self) -> float:
        kb = _status_kb("VmRSS")
        return kb / 1024 if kb is not None else float("nan")

    def peak_mb(self) -> float:
        kb = _status_kb("VmHWM") if self.resettable else None
        if kb is None:
            kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return kb / 1024


def machine() -> dict:
    """Returns the CPU model, core count, memory, OS and Python of this machine."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    mem = None
    try:
        with open("/proc/meminfo") as f:
            mem = round(int(next(line.split()[1] for line in f if line.startswith("MemTotal"))) / 2**20, 1)
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "logical_cpus": os.cpu_count(), "memory_gib": mem, "os": platform.platform(),
            "python": platform.python_version()}


def parents_for(dim: int) -> tuple[int, ...]:
    """Returns a kinematic tree of `dim / 3 + 1` joints (root first): five chains from the root, for bone-length losses."""
    j = dim // 3 + 1
    return tuple(-1 if i == 0 else (0 if i % 4 == 1 else i - 1) for i in range(j))


def heatmap_batch(s: Settings, c: Case) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Returns `(cells, batch)` for MotionMap's heatmap step: map cells of a 4,096-window pool, and `c.k` members per window.

    Both frameworks build the step's target maps from these (cells in the map, members as pool
    indices, every member valid), so they time the same work on the same numbers.
    """
    rng = np.random.default_rng(s.seed + 5)
    cells = rng.integers(0, s.hm_size, (4096, 2)).astype(np.int32)
    members = rng.integers(0, len(cells), (c.batch, c.k)).astype(np.int32)
    return cells, {"members": members, "mask": np.ones((c.batch, c.k), bool)}


def gsps_skeleton(dim: int) -> tuple[tuple[int, ...], dict[str, int], tuple[tuple[int, ...], ...], list[list[float]]]:
    """Returns `(parents, roles, parts, bounds)` for GSPS on `parents_for(dim)`'s five chains (at least 20 joints).

    The chains from the root read as right leg (hip, knee, foot), left leg, spine (spine, thorax,
    neck, head), right arm (shoulder, elbow, wrist) and left arm; parts are the legs' nodes, then the
    rest (GSPS's lower / upper body); `bounds` are 17 fixed cosine intervals, two of them open.
    """
    parents = parents_for(dim)
    if len(parents) < 21:
        raise ValueError(f"gsps_skeleton: needs dim >= 60 (five chains of four joints), got {dim}")
    roles = {"root": 0, "r_hip": 1, "r_knee": 2, "r_foot": 3, "l_hip": 5, "l_knee": 6, "l_foot": 7, "thorax": 10,
             "head": 12, "r_shoulder": 13, "r_elbow": 14, "r_wrist": 15, "l_shoulder": 17, "l_elbow": 18, "l_wrist": 19}
    lower = tuple(range(0, 8))
    upper = tuple(range(8, len(parents) - 1))
    bounds = [[-0.8 + 0.05 * i, 0.3 + 0.03 * i] for i in range(17)]
    bounds[2][0], bounds[9][1] = -1.0, 1.0
    return parents, roles, (lower, upper), bounds
