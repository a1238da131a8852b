"""jaxmotion vs PyTorch, the same networks side by side: one command, one process per framework.

    python benchmarks/run.py --tag NAME   # full run (2-core CPU: about 10 minutes): benchmarks/results/NAME.json and .md
    python benchmarks/run.py --quick      # smoke test: tiny sizes, seconds per case

Workers run one after the other (never concurrently, so they do not share cores):
`benchmarks/jax_bench.py` (jaxmotion), `benchmarks/torch_ref/bench.py` eager, and the same under
`torch.compile` for the cases named by `--compile-cases`. Each writes its records; this script merges
them into `benchmarks/results/<tag>.json` and renders its tables into `<tag>.md`, with ratios
PyTorch time / jaxmotion time (> 1: jaxmotion is faster). The documentation's Benchmarks page is
rendered from the committed results files by `docs/generate.py` (its `SPEED_RUNS` names them). On a shared machine, run it under
the lock: `flock /tmp/jaxmotion-heavy.lock python benchmarks/run.py`.

Roofline: before the cases, `benchmarks/peak.py` measures each framework's rate on large float32
(and, where the CPU has the instructions, bfloat16) matrix products; the machine's peak is the
higher float32 figure. Each case's FLOPs are XLA's cost analysis of the jaxmotion function with
its scans unrolled (`benchmarks/flops.py`), and the same count divides the PyTorch times, so
"% of peak" compares useful work per second. A hand count of one case checks the count.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.harness import MODELS, Settings, machine  # noqa: E402
from jaxmotion.train import hugepages  # noqa: E402

TARGETS = {"train": 1.5, "sample_k50": 2.0, "ddim_100": 3.0}  # jaxmotion / PyTorch-eager speed-ups asked for
# Issue 18: a case whose jaxmotion time is above this fraction of the measured peak is limited by the machine.
MACHINE_LIMITED = 0.6
WORKERS = {
    "jax": ["-m", "benchmarks.jax_bench"],
    "torch_eager": ["-m", "benchmarks.torch_ref.bench"],
    "torch_compile": ["-m", "benchmarks.torch_ref.bench", "--compile"],
}


def worker_env(huge: bool) -> dict:
    """Returns the environment of every worker and peak process: the same for both frameworks.

    `huge`: glibc's huge-page tunable on (`jaxmotion/train/hugepages.py`; what the `jaxmotion` command
    runs with where the kernel's mode is `madvise`), else taken out of `GLIBC_TUNABLES`. PyTorch's
    CPU allocator also takes its large tensors from glibc, so both frameworks get the same setting.
    """
    return hugepages.with_tunable(dict(os.environ, PYTHONPATH=str(ROOT)), on=huge)


def jax_env(env: dict, settings: Settings) -> dict:
    """Returns the jax worker's environment: `env` with `settings.jax_host_devices` CPU host devices forced."""
    from jaxmotion.train.host_devices import host_device_env

    return env if settings.jax_host_devices <= 1 else host_device_env(env, settings.jax_host_devices)


def run_worker(name: str, settings: Settings, extra: list[str], env: dict) -> dict:
    """Returns the worker's `{"info", "records"}` after running it in a fresh Python process."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"{name}.json"
        cmd = [sys.executable, *WORKERS[name], "--settings", json.dumps(dataclasses.asdict(settings)), "--out", str(out), *extra]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, env=env)
        if proc.returncode != 0:
            raise RuntimeError(f"benchmark worker {name!r} failed with exit code {proc.returncode}: {' '.join(cmd)}")
        result = json.loads(out.read_text())
    result["info"]["process_wall_s"] = time.perf_counter() - t0
    return result


def run_peak(framework: str, settings: Settings, env: dict) -> dict:
    """Returns `benchmarks/peak.py`'s measurement of `framework` ("jax" or "torch"), run in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "peak.json"
        cmd = [sys.executable, "-m", "benchmarks.peak", "--framework", framework, "--out", str(out),
               "--sizes", ",".join(map(str, settings.peak_sizes))]
        if subprocess.run(cmd, cwd=ROOT, env=env).returncode != 0:
            raise RuntimeError(f"peak measurement failed: {' '.join(cmd)}")
        return json.loads(out.read_text())


ROW_KEYS = ("case", "model", "kind", "batch", "k", "t_pred", "steps")  # a case's fields in a row (`steps`: 0 in older files)


def merge(results: dict[str, dict]) -> list[dict]:
    """Returns one row per case with every framework's record and the ratios to jaxmotion."""
    rows: dict[str, dict] = {}
    for fw, res in results.items():
        for r in res["records"]:
            row = rows.setdefault(r["case"], {k: r.get(k, 0) for k in ROW_KEYS})
            row[fw] = {k: v for k, v in r.items() if k not in row}
    for row in rows.values():
        jax_t = row.get("jax", {}).get("median_s")
        for fw in ("torch_eager", "torch_compile"):
            t = row.get(fw, {}).get("median_s")
            if jax_t and t:
                row[f"ratio_{fw}"] = t / jax_t
    return list(rows.values())


# ---------------------------------------------------------------------------------------------
# Markdown.


def _ms(rec: dict | None) -> str:
    if not rec or "median_s" not in rec:
        return "failed" if rec and "error" in rec else "-"
    return f"{rec['median_s'] * 1e3:.3g} ({rec['p25_s'] * 1e3:.3g}-{rec['p75_s'] * 1e3:.3g})"


def _ratio(row: dict, fw: str) -> str:
    r = row.get(f"ratio_{fw}")
    return f"{r:.2f}x" if r else "-"


def _wps(row: dict, fw: str) -> str:
    rec = row.get(fw)
    return f"{row['batch'] / rec['median_s']:.0f}" if rec and "median_s" in rec else "-"


PEAK_OF = {"jax": "jax", "torch_eager": "torch", "torch_compile": "torch"}  # whose peak.py measurement


def machine_peak(doc: dict) -> float | None:
    """Returns this machine's float32 peak in GFLOP/s: the higher of the frameworks' large-product rates."""
    rates = [p["peak_gflops"]["float32"] for p in doc.get("peak", {}).values()]
    return max(rates) if rates else None


def _gflops(row: dict, fw: str) -> float | None:
    """Returns the case's useful work rate under `fw`: jaxmotion's FLOP count of the case / `fw`'s time."""
    rec, flops = row.get(fw), row.get("jax", {}).get("flops")
    return flops / rec["median_s"] / 1e9 if rec and "median_s" in rec and flops else None


def _pct(row: dict, fw: str, peak: float | None) -> str:
    g = _gflops(row, fw)
    if g is None or not peak:
        return "-"
    v = 100 * g / peak
    return f"{v:.0f}%" if v >= 10 else f"{v:.1f}%"


def _pcts(row: dict, fws: tuple[str, ...], peak: float | None) -> str:
    return " / ".join(_pct(row, fw, peak) for fw in fws)


def probe_gflops(row: dict, s: Settings) -> float | None:
    """Returns jax's rate on the fixed `probe_n`^3 product measured around the case (`harness.measure`), GFLOP/s.

    The median of the probes after each call (calls of `probe_min_call_s` or more) or of the two
    bracketing the case (shorter calls): a record of the machine's state around the case. On the
    2-core AMD EPYC of benchmarks/results/targets.md it is ~450 GFLOP/s (the measured peak) or about half, and
    it does not track every case's speed: in the three runs of the generated tables five cases ran faster than
    the probe around them (up to 136% of it), so it is shown, not used to judge a target.
    """
    ms = row.get("jax", {}).get("probe_ms_median")
    return 2 * s.probe_n ** 3 / (ms * 1e-3) / 1e9 if ms and s.probe_n else None


def _during(row: dict, s: Settings) -> str:
    g, p = _gflops(row, "jax"), probe_gflops(row, s)
    return f"{p:.0f} ({100 * g / p:.0f}%)" if g is not None and p else "-"


def _gflop(row: dict) -> str:
    f = row.get("jax", {}).get("flops")
    return f"{f / 1e9:.3g}" if f else "-"


def _target(row: dict, s: Settings, peak: float | None = None) -> str:
    r = row.get("ratio_torch_eager")
    g = _gflops(row, "jax")
    at_limit = bool(peak and g is not None and g / peak > MACHINE_LIMITED)
    if row["kind"].startswith("train"):
        goal = TARGETS["train"]
    elif row["kind"] == "sample" and row["k"] == s.k:
        goal = TARGETS["sample_k50"]
    elif row["kind"] == "sample_ddim" and row.get("steps") == 100 and row["k"] == s.k:
        goal = TARGETS["ddim_100"]
    else:
        return ""
    if r is None:
        return "?"
    if r >= goal:
        return f"met (>= {goal}x)"
    if at_limit:
        return f"machine-limited (> {MACHINE_LIMITED:.0%} of peak; PyTorch trails by {r:.2f}x)"
    return f"**missed** (< {goal}x)"


def render(doc: dict) -> str:
    """Returns the markdown section (tables, machine, versions, command) for one run."""
    s = Settings.from_record(doc["settings"])
    rows = doc["rows"]
    info = doc["workers"]
    m = doc["machine"]
    peak = machine_peak(doc)
    eager, compiled = ("jax", "torch_eager"), ("jax", "torch_eager", "torch_compile")
    lines = [
        f"Run {doc['date']} on **{m['cpu']}**, {m['logical_cpus']} logical CPUs, {m['memory_gib']} GiB "
        f"({m['os']}, Python {m['python']}); "
        + ", ".join(f"{k} {v}" for k, v in {k: v for w in info.values() for k, v in w["info"]["versions"].items()}.items())
        + f"; PyTorch threads: {info.get('torch_eager', {}).get('info', {}).get('threads', '?')}.",
        "",
        f"Command: `{doc['command']}` (whole run: {doc['wall_s'] / 60:.1f} min). Sizes: D = {s.dim}, "
        f"t_his = {s.t_his}, t_pred = {s.t_pred} (Bandai-Namco-2's protocol), the published layer sizes. "
        f"Every time is the median of {s.repeats} runs after {s.warmup} warm-up runs, with the interquartile "
        "range in brackets, in milliseconds. Ratio = PyTorch time / jaxmotion time (> 1: jaxmotion faster). "
        + _pages_sentence(doc) + _slow_sentence(doc, s),
        "",
        _peak_paragraph(doc, peak),
        "",
        "### Training throughput",
        "",
        "| model | stage | batch | jaxmotion ms | PyTorch eager ms | ratio (eager) | windows/s jax / eager | GFLOP | % of peak jax / eager | target |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        if r["kind"].startswith("train"):
            stage = {"train_cvae": "CVAE", "train_ae": "autoencoder", "train_heatmap": f"heatmap ({r['k']} futures per map)",
                     "train_generator": f"generator (nk1 x nk2 = {r['k']})"}.get(r["kind"], f"sampler (K = {r['k']})")
            lines.append(f"| {r['model']} | {stage} | {r['batch']} | {_ms(r.get('jax'))} | {_ms(r.get('torch_eager'))} | "
                         f"{_ratio(r, 'torch_eager')} | {_wps(r, 'jax')} / {_wps(r, 'torch_eager')} | {_gflop(r)} | "
                         f"{_pcts(r, eager, peak)} | {_target(r, s, peak)} |")
    lines += [
        "",
        f"### Sampling K = {s.k} futures (the method's own sampler)",
        "",
        "| model | batch | jaxmotion ms | PyTorch eager ms | torch.compile ms | ratio (eager) | ratio (compile) | GFLOP | % of peak jax / eager / compile | target |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        if r["kind"] == "sample":
            lines.append(f"| {r['model']} | {r['batch']} | {_ms(r.get('jax'))} | {_ms(r.get('torch_eager'))} | "
                         f"{_ms(r.get('torch_compile'))} | {_ratio(r, 'torch_eager')} | {_ratio(r, 'torch_compile')} | "
                         f"{_gflop(r)} | {_pcts(r, compiled, peak)} | {_target(r, s, peak)} |")
    lines += _ddim_table(rows, s, peak)
    heat = [r for r in rows if r["kind"] == "heatmap"]
    if heat:
        lines += [
            "",
            f"### MotionMap's heatmap network ({s.hm_size} x {s.hm_size} map of each window, sigmoid included)",
            "",
            "| model | batch | jaxmotion ms | PyTorch eager ms | torch.compile ms | ratio (eager) | ratio (compile) | GFLOP | % of peak jax / eager / compile |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for r in heat:
            lines.append(f"| {r['model']} | {r['batch']} | {_ms(r.get('jax'))} | {_ms(r.get('torch_eager'))} | "
                         f"{_ms(r.get('torch_compile'))} | {_ratio(r, 'torch_eager')} | {_ratio(r, 'torch_compile')} | "
                         f"{_gflop(r)} | {_pcts(r, compiled, peak)} |")
    for axis, label in (("k", "K"), ("t_pred", "t_pred")):
        lines += [
            "",
            f"### Latency vs {label} (batch 1, CVAE decoder on N(0, I) latents)",
            "",
            f"| model | {label} | jaxmotion ms | PyTorch eager ms | ratio |",
            "| --- | --- | --- | --- | --- |",
        ]
        fixed = "t_pred" if axis == "k" else "k"
        sel = [r for r in rows if r["kind"] == "sample_prior" and r[fixed] == getattr(s, fixed)]
        for r in sorted(sel, key=lambda r: (MODELS.index(r["model"]), r[axis])):
            lines.append(f"| {r['model']} | {r[axis]} | {_ms(r.get('jax'))} | {_ms(r.get('torch_eager'))} | {_ratio(r, 'torch_eager')} |")
    lines += _roofline(rows, peak, s)
    lines += [
        "",
        "### Peak memory and jaxmotion compile time",
        "",
        "Peak RSS = the process's resident-set high-water mark during the case (Linux `VmHWM`, reset per case "
        "through `/proc/self/clear_refs`), process baseline (interpreter, libraries) included; compile = "
        "jaxmotion's tracing + XLA compilation (`jit(...).lower(...).compile()`), and for torch.compile its "
        "first (compiling) call; neither is in the timings above.",
        "",
        "| case | jaxmotion peak MB (+ during case) | PyTorch eager peak MB (+ during case) | jaxmotion trace + compile s | torch.compile first call s |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        if r["kind"] != "sample_prior" or (r["k"] in (1, 1000) and r["t_pred"] == s.t_pred):
            j, e, c = r.get("jax", {}), r.get("torch_eager", {}), r.get("torch_compile", {})
            mb = lambda rec: f"{rec['peak_rss_mb']:.0f} (+{rec['peak_rss_mb'] - rec['rss_before_mb']:.0f})" if "peak_rss_mb" in rec else "-"
            comp = f"{j['trace_s'] + j['compile_s']:.1f}" if "compile_s" in j else "-"
            tc = f"{c['compile_s']:.0f}" if c.get("compile_s") == c.get("compile_s") and "compile_s" in c else "-"
            lines.append(f"| {r['case']} | {mb(j)} | {mb(e)} | {comp} | {tc} |")
    return "\n".join(lines)


def _ddim_table(rows: list[dict], s: Settings, peak: float | None) -> list[str]:
    """Returns the diffusion predictor's sampling table (DDIM with DCT completion, by steps and batch); nothing without its rows."""
    ddim = sorted((r for r in rows if r["kind"] == "sample_ddim"), key=lambda r: (-r["steps"], r["batch"]))
    if not ddim:
        return []
    lines = [
        "",
        f"### Diffusion sampling: K = {s.k} futures by DDIM with DCT completion (jaxmotion: one `lax.scan` over the "
        "steps, the K samples in the batch of every product; PyTorch: the release's Python loop over the steps)",
        "",
        f"Denoiser of `DiffusionConfig`'s defaults (Bandai CPU sizes). Median of {s.ddim_repeats} calls after "
        f"{s.ddim_warmup} warm-up call(s)."
        + (f" jaxmotion's K samples split over {s.jax_host_devices} CPU host devices (`sample(devices=...)`, "
           f"`XLA_FLAGS=--xla_force_host_platform_device_count={s.jax_host_devices}`), {s.k // s.jax_host_devices} on each."
           if s.jax_host_devices > 1 else ""),
        "",
        "| DDIM steps | batch | jaxmotion ms | PyTorch eager ms | torch.compile ms | ratio (eager) | ratio (compile) | GFLOP | % of peak jax / eager / compile | target |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    compiled = ("jax", "torch_eager", "torch_compile")
    for r in ddim:
        lines.append(f"| {r['steps']} | {r['batch']} | {_ms(r.get('jax'))} | {_ms(r.get('torch_eager'))} | "
                     f"{_ms(r.get('torch_compile'))} | {_ratio(r, 'torch_eager')} | {_ratio(r, 'torch_compile')} | "
                     f"{_gflop(r)} | {_pcts(r, compiled, peak)} | {_target(r, s, peak)} |")
    return lines


def _slow_sentence(doc: dict, s: Settings) -> str:
    """Returns what the machine-speed gate of `harness.measure` left out in this run (nothing for runs before it)."""
    recs = [(r["case"], fw, r[fw]) for r in doc["rows"] for fw in ("jax", "torch_eager", "torch_compile")
            if "calls" in r.get(fw, {})]
    if not recs or s.slow_factor <= 1:
        return ""
    head = (f" Calls of {s.probe_min_call_s * 1e3:g} ms or more are each followed by a fixed {s.probe_n} x {s.probe_n} "
            f"product in the same framework, and a call whose product took more than {s.slow_factor:g}x its fastest "
            "is not counted (the machine was slow then; `harness.measure`)")
    slow = [(c, fw, r) for c, fw, r in recs if r["slow_calls"]]
    if not slow:
        return head + f": no call was left out ({len(recs)} probed cases)."
    names = {"jax": "jaxmotion", "torch_eager": "eager", "torch_compile": "compile"}
    return head + ". Left out: " + "; ".join(f"{c} {names[fw]} {r['slow_calls']} of {r['calls']}" for c, fw, r in slow) + "."


def _pages_sentence(doc: dict) -> str:
    """Returns what memory pages both frameworks' processes ran with (`--hugepages`)."""
    pages = doc.get("memory_pages")
    if pages is None:
        return "Memory pages: the system's default (run before `--hugepages` existed)."
    on = hugepages.has_tunable({"GLIBC_TUNABLES": pages["glibc_tunables"]})
    return (f"Memory pages, both frameworks: `GLIBC_TUNABLES={pages['glibc_tunables']}` (huge pages for large buffers)"
            if on else "Memory pages, both frameworks: glibc's default (`--hugepages off`)") + \
        f", kernel transparent-huge-page mode `{pages['thp_mode']}`."


def _peak_paragraph(doc: dict, peak: float | None) -> str:
    """Returns the sentence that says what the machine's peak is and how "% of peak" is computed."""
    pk = doc.get("peak", {})
    if not pk:
        return "No peak measured in this run (no `peak` in the results file): no \"% of peak\" figures."
    names = {"jax": "jax", "torch": "PyTorch"}
    rates = "; ".join(f"{names[fw]} " + ", ".join(f"{dt} {v:.0f}" for dt, v in p["peak_gflops"].items())
                      for fw, p in pk.items())
    first = next(iter(pk.values()))
    bf16 = ", ".join(first.get("bf16_instructions", [])) or "none (bfloat16 not measured)"
    return (f"Peak, measured in this run (`benchmarks/peak.py`: n x n matrix products, n = "
            f"{'/'.join(map(str, first['sizes']))}, the best n), GFLOP/s: {rates}. CPU bfloat16 instructions: {bf16}. "
            f"% of peak = the case's FLOPs (XLA's cost analysis of the jaxmotion function with its scans unrolled, "
            f"`benchmarks/flops.py`) / its time / {peak:.0f} GFLOP/s, the higher float32 figure. PyTorch's times are "
            "divided by the same FLOP count (its twins do somewhat more work in DLow's and MOJO's decoders), so the "
            "figure is useful work per second.")


def _roofline(rows: list[dict], peak: float | None, s: Settings) -> list[str]:
    """Returns the roofline table (every case) and the hand check of the FLOP count; nothing for a run without counts."""
    if not any("flops" in r.get("jax", {}) for r in rows):
        return []
    lines = [
        "",
        "### Roofline: FLOPs and the fraction of the measured peak, every case",
        "",
        "GFLOP = XLA's cost analysis with the scans unrolled (matrix products and elementwise work); "
        "products = the matrix products' share, counted from the jaxpr; XLA compiled = "
        "`compiled.cost_analysis()` of the executable that runs, which counts a loop body once.",
        "",
        f"jax probe = the rate of jax's fixed {s.probe_n} x {s.probe_n} float32 product measured around the case "
        "(after each call, or before and after the case for calls under "
        f"{s.probe_min_call_s * 1e3:g} ms; `harness.measure`), GFLOP/s, and the case's rate as a % of it: a record "
        "of the machine's state around the case (about half the peak in its slow stretches), not a limit: a case "
        "can run faster than the probe beside it.",
        "",
        "| case | GFLOP | products | XLA compiled GFLOP | jaxmotion GFLOP/s (% of peak) | PyTorch eager GFLOP/s (% of peak) | torch.compile GFLOP/s (% of peak) | jax probe GFLOP/s (jaxmotion's % of it) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    rate = lambda r, fw: f"{_gflops(r, fw):.3g} ({_pct(r, fw, peak)})" if _gflops(r, fw) is not None else "-"  # noqa: E731
    for r in rows:
        j = r.get("jax", {})
        if "flops" not in j:
            continue
        lines.append(f"| {r['case']} | {j['flops'] / 1e9:.3g} | {100 * j['matmul_flops'] / j['flops']:.0f}% | "
                     f"{j['xla_compiled_flops'] / 1e9:.3g} | {rate(r, 'jax')} | {rate(r, 'torch_eager')} | "
                     f"{rate(r, 'torch_compile')} | {_during(r, s)} |")
    checked = [r for r in rows if "hand_matmul_flops" in r.get("jax", {})]
    check = next((r for r in checked if (r["k"], r["t_pred"]) == (s.k, s.t_pred)), checked[0] if checked else None)
    if check:
        j = check["jax"]
        lines += ["", f"Check of the count, {check['case']}: matrix products by hand {j['hand_matmul_flops'] / 1e9:.6f} "
                  f"GFLOP (`flops.dlow_prior_hand_count`), from the jaxpr {j['matmul_flops'] / 1e9:.6f}; XLA with the "
                  f"scans unrolled {j['flops'] / 1e9:.6f} (the products plus elementwise work); XLA's compiled "
                  f"executable {j['xla_compiled_flops'] / 1e9:.6f} (the decoder's {check['t_pred']}-step loop counted once)."]
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny sizes and repeats (smoke test)")
    ap.add_argument("--models", default=",".join(MODELS), help=f"comma-separated subset of {','.join(MODELS)}")
    ap.add_argument("--repeats", type=int, help="timed runs per case (default 7; quick 2)")
    ap.add_argument("--warmup", type=int, help="untimed runs per case before timing (default 2; quick 1)")
    ap.add_argument("--compile-cases", default="sample,heatmap",
                    help="case kinds also run under torch.compile ('' for none; e.g. 'sample,train_cvae'); "
                         "compiling a 60-step training graph takes minutes on a 2-core CPU")
    ap.add_argument("--frameworks", default="jax,torch_eager,torch_compile",
                    help="workers to run; with --update, the others' records are kept from the results file")
    ap.add_argument("--update", action="store_true",
                    help="re-run only --frameworks and merge them into the existing results file of --tag")
    ap.add_argument("--tag", help="results file name (default: cpu, or quick)")
    ap.add_argument("--no-readme", action="store_true", help="accepted for older commands; nothing updates a README")
    ap.add_argument("--hugepages", choices=("on", "off"), default="on",
                    help="glibc's huge-page tunable for every worker, both frameworks (jaxmotion/train/hugepages.py; default on, "
                         "as the jaxmotion command runs)")
    ap.add_argument("--slow-factor", type=float,
                    help="leave out a call whose probe product after it took more than this times its fastest "
                         "(harness.measure's gate, e.g. 1.5; default 0: off, every call counted and the probe recorded)")
    ap.add_argument("--ddim-steps", help="the diffusion sampler's DDIM steps, comma-separated (default 100,10)")
    ap.add_argument("--jax-host-devices", type=int,
                    help="CPU host devices of the jax worker; the diffusion sampler splits K over them (default 1)")
    ap.add_argument("--render", action="store_true", help="only re-render the tables from the results file of --tag")
    args = ap.parse_args(argv)
    if args.render:
        out = ROOT / "benchmarks" / "results" / f"{args.tag or 'cpu'}.json"
        section = render(json.loads(out.read_text()))
        out.with_suffix(".md").write_text(section + "\n")
        print(section)
        return
    models = tuple(m for m in args.models.split(",") if m)
    unknown = set(models) - set(MODELS)
    if unknown:
        ap.error(f"--models: unknown {sorted(unknown)}; known: {','.join(MODELS)}")
    kw = {"models": models}
    if args.repeats is not None:
        kw["repeats"] = args.repeats
    if args.warmup is not None:
        kw["warmup"] = args.warmup
    if args.ddim_steps:
        kw["ddim_steps"] = tuple(int(v) for v in args.ddim_steps.split(","))
    if args.jax_host_devices is not None:
        if args.jax_host_devices < 1:
            ap.error(f"--jax-host-devices must be 1 or more, got {args.jax_host_devices}")
        kw["jax_host_devices"] = args.jax_host_devices
    if args.slow_factor is not None:
        if args.slow_factor < 0 or 0 < args.slow_factor <= 1:
            ap.error(f"--slow-factor must be 0 (off) or above 1, got {args.slow_factor}")
        kw["slow_factor"] = args.slow_factor
    settings = Settings.quick(**kw) if args.quick else Settings(**kw)
    if settings.k % settings.jax_host_devices:
        ap.error(f"--jax-host-devices {settings.jax_host_devices}: K = {settings.k} does not split evenly over them")
    tag = args.tag or ("quick" if args.quick else "cpu")
    out = ROOT / "benchmarks" / "results" / f"{tag}.json"
    frameworks = [f for f in args.frameworks.split(",") if f]
    if set(frameworks) - set(WORKERS):
        ap.error(f"--frameworks: unknown {sorted(set(frameworks) - set(WORKERS))}; known: {','.join(WORKERS)}")
    results, previous = {}, None
    if args.update:
        if not out.exists():
            ap.error(f"--update: no results file {out} to update")
        previous = json.loads(out.read_text())
        settings = Settings.from_record(previous["settings"])
        for fw, w in previous["workers"].items():
            if fw not in frameworks:
                results[fw] = {"info": w["info"], "records": [r[fw] | {k: r.get(k, 0) for k in ROW_KEYS}
                                                              for r in previous["rows"] if fw in r]}
    t0 = time.perf_counter()
    peaks = dict(previous.get("peak", {})) if previous else {}
    env = worker_env(args.hugepages == "on")
    for fw in dict.fromkeys(PEAK_OF[f] for f in frameworks if f != "torch_compile" or args.compile_cases):
        peaks[fw] = run_peak(fw, settings, env)
    for fw in frameworks:
        if fw == "torch_compile" and not args.compile_cases:
            continue
        results[fw] = run_worker(fw, settings, ["--cases", args.compile_cases] if fw == "torch_compile" else [],
                                 jax_env(env, settings) if fw == "jax" else env)
    results = {fw: results[fw] for fw in WORKERS if fw in results}
    doc = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "command": "python benchmarks/run.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "machine": machine(),
        # What every worker ran with (`worker_env`); a run without this key predates the option (no tunable).
        "memory_pages": {"glibc_tunables": env.get("GLIBC_TUNABLES", ""), "thp_mode": hugepages.thp_mode()},
        "settings": dataclasses.asdict(settings),
        "workers": {k: {"info": v["info"]} for k, v in results.items()},
        "peak": peaks,
        "rows": merge(results),
    }
    doc["wall_s"] = time.perf_counter() - t0
    if previous is not None:
        doc["command"] = previous["command"] + f"; then `{doc['command']}`"
        doc["wall_s"] += previous["wall_s"]
        doc["updated"] = doc["date"]
        doc["date"] = previous["date"]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    section = render(doc)
    (out.with_suffix(".md")).write_text(section + "\n")
    print(section)
    print(f"\nwrote {out} ({doc['wall_s'] / 60:.1f} min)")


if __name__ == "__main__":
    main()
