"""This machine's measured peak: the rate of large matrix products in one framework, float32 and bfloat16.

Run by `benchmarks/run.py` in its own process, once per framework, in the same run as the cases
(`python -m benchmarks.peak --framework jax|torch --out FILE`). Square n x n products for n = 1024,
2048, 4096, each the median of a few calls after a warm-up; the peak is the best n. bfloat16
(float32 accumulation) is measured only where the CPU has bfloat16 instructions (`avx512_bf16` or
`amx_bf16` in /proc/cpuinfo) or the device is not a CPU; elsewhere it would be emulated, not a peak.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

SIZES = (1024, 2048, 4096)


def cpu_flags() -> set[str]:
    """Returns the CPU's feature flags (Linux /proc/cpuinfo; empty elsewhere)."""
    try:
        with open("/proc/cpuinfo") as f:
            return set(next(line for line in f if line.startswith("flags")).split(":", 1)[1].split())
    except (OSError, StopIteration):
        return set()


def has_bf16(flags: set[str]) -> bool:
    return bool({"avx512_bf16", "amx_bf16"} & flags)


def _rates(matmul, make, sizes) -> dict[int, float]:
    return {n: _rate(matmul, make, n, 5 if n < 4096 else 3) for n in sizes}


def _rate(matmul, make, n: int, repeats: int) -> float:
    """Returns the GFLOP/s of `matmul(a, b)` on n x n operands (median of `repeats` calls after one warm-up)."""
    a, b = make(n, 0), make(n, 1)
    matmul(a, b)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        matmul(a, b)
        times.append(time.perf_counter() - t0)
    return 2 * n**3 / statistics.median(times) / 1e9


def _jax(dtypes, sizes):
    import jax
    import jax.numpy as jnp
    import numpy as np

    if jax.devices()[0].platform != "cpu" and "bfloat16" not in dtypes:
        dtypes = [*dtypes, "bfloat16"]
    out = {}
    for name in dtypes:
        dt = {"float32": jnp.float32, "bfloat16": jnp.bfloat16}[name]
        f = jax.jit(lambda a, b: jnp.dot(a, b, preferred_element_type=jnp.float32))
        make = lambda n, s, dt=dt: jnp.asarray(np.random.default_rng(s).normal(size=(n, n)), dt)  # noqa: E731
        out[name] = _rates(lambda a, b: f(a, b).block_until_ready(), make, sizes)
    return out, {"jax": jax.__version__, "device": str(jax.devices()[0])}


def _torch(dtypes, sizes):
    import torch

    out = {}
    for name in dtypes:
        dt = {"float32": torch.float32, "bfloat16": torch.bfloat16}[name]
        make = lambda n, s, dt=dt: torch.randn(n, n, generator=torch.Generator().manual_seed(s)).to(dt)  # noqa: E731
        out[name] = _rates(torch.mm, make, sizes)
    return out, {"torch": torch.__version__, "threads": torch.get_num_threads()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--framework", choices=("jax", "torch"), required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)), help="matrix sides n, comma-separated")
    args = ap.parse_args()
    sizes = [int(n) for n in args.sizes.split(",")]
    flags = cpu_flags()
    dtypes = ["float32"] + (["bfloat16"] if has_bf16(flags) else [])
    rates, info = (_jax if args.framework == "jax" else _torch)(dtypes, sizes)
    doc = {"framework": args.framework, "sizes": sizes, "gflops_by_size": rates,
           "peak_gflops": {k: max(v.values()) for k, v in rates.items()},
           "bf16_instructions": sorted({"avx512_bf16", "amx_bf16", "amx_tile"} & flags), **info}
    for k, v in doc["peak_gflops"].items():
        print(f"peak {args.framework} {k}: {v:.1f} GFLOP/s", flush=True)
    with open(args.out, "w") as f:
        json.dump(doc, f, indent=1)


if __name__ == "__main__":
    main()
