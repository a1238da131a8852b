"""benchmarks/harness.measure's machine-speed gate: calls made while the probe product ran slow are not counted."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks import harness  # noqa: E402


class FakeClock:
    """A clock that only moves when the scripted `run` or `probe` is called."""

    def __init__(self, monkeypatch):
        self.now = 0.0
        monkeypatch.setattr(harness.time, "perf_counter", lambda: self.now)

    def scripted(self, durations, twice=False):
        """Returns a call taking the given durations in turn; `twice`: each is taken by two calls (a probe's warm-up and timed call)."""
        it = iter([d for d in durations for _ in range(2 if twice else 1)])

        def call():
            self.now += next(it)
        return call


def test_calls_followed_by_a_slow_probe_are_left_out_and_replaced(monkeypatch):
    clock = FakeClock(monkeypatch)
    # 2 warm-up calls, then calls 3-5 ran while the machine was at half speed (call and probe both 2x).
    run = clock.scripted([0.06, 0.06] + [0.06, 0.06, 0.12, 0.12, 0.12, 0.06, 0.06, 0.06])
    probe = clock.scripted([0.010, 0.010, 0.010] + [0.010, 0.011, 0.020, 0.021, 0.020, 0.010, 0.010, 0.011], twice=True)
    rec = harness.measure(run, warmup=2, repeats=5, probe=probe, slow_factor=1.5)
    assert rec["calls"] == 8 and rec["slow_calls"] == 3 and rec["n"] == 5
    assert rec["median_s"] == pytest.approx(0.06) and rec["max_s"] == pytest.approx(0.06)
    assert rec["probe_ms_min"] == pytest.approx(10.0)


def test_without_a_slow_stretch_nothing_is_left_out(monkeypatch):
    clock = FakeClock(monkeypatch)
    run = clock.scripted([0.05] * 2 + [0.05, 0.07, 0.06])
    probe = clock.scripted([0.01] * 3 + [0.012, 0.010, 0.011], twice=True)
    rec = harness.measure(run, warmup=2, repeats=3, probe=probe, slow_factor=1.5)
    assert (rec["calls"], rec["slow_calls"], rec["n"]) == (3, 0, 3) and rec["median_s"] == pytest.approx(0.06)


def test_a_machine_slow_throughout_stops_after_max_calls_and_keeps_the_best_probed_call(monkeypatch):
    clock = FakeClock(monkeypatch)
    # The pre-probes were fast, every probe after a call slow: the gate gives up after 3 x repeats calls.
    run = clock.scripted([0.05] * 2 + [0.1, 0.1, 0.09, 0.1, 0.1, 0.1])
    probe = clock.scripted([0.01] * 3 + [0.03, 0.03, 0.02, 0.03, 0.03, 0.03], twice=True)
    rec = harness.measure(run, warmup=2, repeats=2, probe=probe, slow_factor=1.5)
    assert (rec["calls"], rec["slow_calls"], rec["n"]) == (6, 5, 1)
    assert rec["median_s"] == pytest.approx(0.09)


def test_short_calls_are_bracketed_by_probes_not_probed_one_by_one(monkeypatch):
    clock = FakeClock(monkeypatch)
    events = []
    timed = clock.scripted([0.001] * 5)
    probe_t = clock.scripted([0.004, 0.008], twice=True)  # the machine slowed down during the case

    def run():
        events.append("run")
        timed()

    def probe():
        events.append("probe")
        probe_t()
    rec = harness.measure(run, warmup=2, repeats=3, probe=probe, ref_s=0.002)
    # One probe (two calls: warm-up and timed) before the warm-up calls, one after the timed calls, none between.
    assert events == ["probe"] * 2 + ["run"] * 5 + ["probe"] * 2
    assert rec["n"] == 3 and "calls" not in rec and rec["median_s"] == pytest.approx(0.001)
    assert rec["bracket_probe_ms"] == pytest.approx([4.0, 8.0])
    assert rec["probe_ms_median"] == pytest.approx(6.0) and rec["probe_ms_min"] == pytest.approx(2.0)
    assert "probe_ms_min" not in harness.measure(clock.scripted([0.001] * 5), warmup=2, repeats=3)


def test_a_case_run_entirely_in_a_slow_stretch_is_judged_against_the_workers_reference(monkeypatch):
    clock = FakeClock(monkeypatch)
    # The worker measured 2 ms at its start; this whole case ran at 4 ms probes: every call is left out.
    run = clock.scripted([0.06] * 2 + [0.09] * 6)
    probe = clock.scripted([0.004] * 9, twice=True)
    rec = harness.measure(run, warmup=2, repeats=2, probe=probe, ref_s=0.002, slow_factor=1.5)
    assert (rec["calls"], rec["slow_calls"]) == (6, 5) and rec["probe_ms_min"] == pytest.approx(2.0)
    assert harness.measure(clock.scripted([0.06] * 4), 2, 2, clock.scripted([0.004] * 5, twice=True), slow_factor=1.5)["slow_calls"] == 0


def test_by_default_every_call_counts_and_the_probe_is_recorded(monkeypatch):
    clock = FakeClock(monkeypatch)
    run = clock.scripted([0.06] * 2 + [0.06, 0.12, 0.06])
    probe = clock.scripted([0.010] * 3 + [0.010, 0.020, 0.011], twice=True)
    rec = harness.measure(run, warmup=2, repeats=3, probe=probe)
    assert (rec["calls"], rec["slow_calls"], rec["n"]) == (3, 0, 3) and rec["max_s"] == pytest.approx(0.12)
    assert rec["probe_ms_min"] == pytest.approx(10.0) and rec["probe_ms_median"] == pytest.approx(11.0)


def test_the_probe_rate_around_a_case_is_recorded_but_does_not_judge_its_target():
    from benchmarks import run

    s = harness.Settings()
    slow_probe_ms = 2 * s.probe_n ** 3 / 232e9 * 1e3  # the probe at 232 GFLOP/s, half the peak
    row = {"kind": "sample", "k": s.k, "ratio_torch_eager": 1.8,
           "jax": {"flops": 2.51e9, "median_s": 11e-3, "probe_ms_median": slow_probe_ms}}
    assert run.probe_gflops(row, s) == pytest.approx(232.0)
    assert run._during(row, s) == "232 (98%)"  # 2.51 GFLOP in 11 ms = 228 GFLOP/s
    # A miss stays a miss however slow the probe beside it ran; above 60% of the peak it is the machine's.
    assert run._target(row, s, 467.0) == "**missed** (< 2.0x)"
    assert run._target(row, s, 300.0).startswith("machine-limited (> 60% of peak; PyTorch trails by 1.80x)")
    assert run.probe_gflops({"jax": {"median_s": 1.0}}, s) is None


def test_settings_from_a_results_file_ignore_knobs_since_removed():
    rec = {"k": 50, "sample_batches": [1, 64], "encoder_backward": "batched"}  # a knob of an older commit
    s = harness.Settings.from_record(rec)
    assert s.k == 50 and s.sample_batches == (1, 64) and not hasattr(s, "encoder_backward")
    with pytest.raises(TypeError, match="encoder_backward"):  # the workers' settings come from this run: no unknown field
        harness.Settings.from_dict(rec)


def test_the_jax_worker_alone_gets_the_host_devices_and_the_table_says_so():
    from benchmarks import run

    env = {"XLA_FLAGS": "--xla_backend_optimization_level=0", "PATH": "/bin"}
    assert run.jax_env(env, harness.Settings()) is env  # one device: the environment as it is
    two = run.jax_env(env, harness.Settings(jax_host_devices=2))
    assert two["XLA_FLAGS"] == "--xla_backend_optimization_level=0 --xla_force_host_platform_device_count=2"
    assert env["XLA_FLAGS"] == "--xla_backend_optimization_level=0" and two["PATH"] == "/bin"  # the others' unchanged
    row = {"case": "diffusion/sample_ddim/b1/k50/t60/s100", "kind": "sample_ddim", "steps": 100, "batch": 1, "k": 50,
           "jax": {"median_s": 0.3, "p25_s": 0.3, "p75_s": 0.3}}
    text = "\n".join(run._ddim_table([row], harness.Settings(jax_host_devices=2), None))
    assert "split over 2 CPU host devices" in text and "25 on each" in text
    assert "host devices" not in "\n".join(run._ddim_table([row], harness.Settings(), None))
    with pytest.raises(SystemExit):  # K = 50 does not split over 3
        run.main(["--jax-host-devices", "3", "--models", "diffusion"])


def test_repro_cost_counts_every_devices_flops_and_puts_host_devices_beside_one():
    from benchmarks import repro_cost

    stage = (lambda s, n: {"stage": "q", "num_steps": 3600, "batch": 32, "step_s": s, "matmul_gflop": 10.0 / n,
                           "rounds_s": [s]})  # noqa: E731
    one = {"config_file": "/x/dlow_humaneva.py", "config": "dlow_humaneva", "stages": [stage(0.8, 1)]}
    two = repro_cost.all_devices({"config_file": "/x/dlow_humaneva.py", "config": "dlow_humaneva", "stages": [stage(0.5, 2)]}, 2)
    assert two["stages"][0]["matmul_gflop"] == 10.0  # the per-device jaxpr's share, times the devices
    doc = {"host_devices": 2, "new": [repro_cost.annotate(one, 100.0)], "host": [repro_cost.annotate(two, 100.0)]}
    assert doc["host"][0]["stages"][0]["pct_peak"] == pytest.approx(20.0)
    rows = repro_cost.host_table(doc).splitlines()
    assert "2 host devices" in rows[0] and len(rows) == 3
    assert rows[2] == "| dlow_humaneva.py | q | 3600 | 32 | 0.800 | 0.500 | 1.60x | 0.8 | 0.5 |"
