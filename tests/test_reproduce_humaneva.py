"""`experiments/reproduce_humaneva.py`: the table's runs in order, skipped when kept, resumed, collected (training faked)."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("reproduce_humaneva", ROOT / "experiments" / "reproduce_humaneva.py")
rh = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rh)


def _fake_run(workdir: Path, name: str, seed: int) -> None:
    """A finished run's files as `jaxmotion run` leaves them: metrics.json and a stage log with curve lines."""
    (workdir / "cvae").mkdir(parents=True)
    (workdir / "metrics.json").write_text(json.dumps([{"config": {"name": name, "seed": seed}, "seed": seed,
                                                       "metrics": {"ADE": 0.25}}]))
    lines = [{"stage": "cvae", "step": s, "curve": True, "predictors": {"cvae": {"APD": 1.0 + s, "ADE": 1.0 / (s + 1),
                                                                                  "FDE": 1.0, "MMADE": 1.0}}}
             for s in (0, 50, 100)]
    (workdir / "cvae" / "log.jsonl").write_text("\n".join(map(json.dumps, lines)) + "\n")


def test_every_listed_config_exists_and_runs_are_unique():
    assert len(set(rh.RUNS)) == len(rh.RUNS)
    for config, seed in rh.RUNS:
        assert (ROOT / "experiments" / "configs" / f"{config}.py").is_file(), config
        assert rh.parse_run(f"{config}:{seed}") == (config, seed)


def test_parse_run_names_what_is_wrong():
    import argparse

    assert rh.parse_run("experiments/configs/dlow_humaneva.py:3") == ("dlow_humaneva", 3)
    with pytest.raises(argparse.ArgumentTypeError, match="expected CONFIG:SEED"):
        rh.parse_run("dlow_humaneva")
    with pytest.raises(argparse.ArgumentTypeError, match="no config experiments/configs/nope.py"):
        rh.parse_run("nope:0")


def test_pending_skips_kept_runs_and_command_resumes(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    (results / "dlow_humaneva_s0_metrics.json").write_text("[]")
    assert rh.pending([("dlow_humaneva", 0), ("dlow_humaneva", 1)], results) == [("dlow_humaneva", 1)]
    work = tmp_path / "dlow_humaneva_s1"
    cmd = rh.command("dlow_humaneva", 1, tmp_path / "he.npz", work, None)
    assert cmd[-2:] == ["--seed", "1"] and "--resume" not in cmd
    (work / "cvae").mkdir(parents=True)
    cmd = rh.command("dlow_humaneva", 1, tmp_path / "he.npz", work, tmp_path / "lock")
    assert cmd[:2] == ["flock", str(tmp_path / "lock")] and cmd[-1] == "--resume"
    cmd = rh.command("dlow_humaneva", 1, tmp_path / "he.npz", work, None, host_devices=2)
    assert cmd[cmd.index("--host-devices") + 1] == "2" and cmd[-1] == "--resume"


def test_main_trains_in_order_collects_and_stops_at_a_failure(tmp_path, monkeypatch, capsys):
    data, runs, results = tmp_path / "he.npz", tmp_path / "runs", tmp_path / "results"
    data.write_bytes(b"x")
    calls, real_run = [], subprocess.run

    def fake(cmd, **kw):
        if "--workdir" not in cmd:  # not a training run (matplotlib may start processes of its own)
            return real_run(cmd, **kw)
        workdir, seed = Path(cmd[cmd.index("--workdir") + 1]), int(cmd[cmd.index("--seed") + 1])
        config = Path(cmd[cmd.index("--config") + 1]).stem
        calls.append((config, seed, "--resume" in cmd))
        assert kw["env"]["PYTHONPATH"].split(":")[0] == str(ROOT)
        if config == "mojo_vae_dct_humaneva":
            return subprocess.CompletedProcess(cmd, 3)
        _fake_run(workdir, config, seed)
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(rh.subprocess, "run", fake)
    (runs / "dlow_humaneva_s1").mkdir(parents=True)  # a run stopped earlier: it resumes
    (runs / "dlow_humaneva_s1" / "ckpt").mkdir()
    argv = ["--data", str(data), "--runs-dir", str(runs), "--results", str(results),
            "--runs", "dlow_humaneva:1", "mojo_vae_dct_humaneva:0", "dlow_humaneva:2"]
    assert rh.main(argv) == 1
    assert calls == [("dlow_humaneva", 1, True), ("mojo_vae_dct_humaneva", 0, False)]
    err = capsys.readouterr().err
    assert "mojo_vae_dct_humaneva seed 0 failed (exit status 3)" in err
    kept = sorted(p.name for p in results.iterdir())
    assert kept == ["dlow_humaneva_s1_curve.json", "dlow_humaneva_s1_curves.png", "dlow_humaneva_s1_metrics.json"]
    curve = json.loads((results / "dlow_humaneva_s1_curve.json").read_text())["curve"]
    assert [p["step"] for p in curve] == [0, 50, 100]
    # Run again: the kept run is skipped, the failed one is tried again.
    calls.clear()
    rh.main(argv)
    assert calls[0] == ("mojo_vae_dct_humaneva", 0, False)


def test_list_and_missing_data(tmp_path, capsys):
    results = tmp_path / "results"
    results.mkdir()
    assert rh.main(["--results", str(results), "--runs-dir", str(tmp_path), "--list"]) == 0
    out = capsys.readouterr().out.split()
    assert out == [f"{c}:{s}" for c, s in rh.RUNS]
    r = subprocess.run([sys.executable, str(ROOT / "experiments" / "reproduce_humaneva.py"), "--data", str(tmp_path / "no.npz"),
                        "--results", str(results), "--runs", "dlow_humaneva:0"], capture_output=True, text=True)
    assert r.returncode == 2 and "is not a file" in r.stderr and "Traceback" not in r.stderr


def test_list_shows_how_far_a_started_run_got(tmp_path, capsys):
    runs = tmp_path / "runs"
    started = runs / "dlow_humaneva_s1"
    for stage, upstream, total, ckpts in (("dlow_k50", {"cvae": 7500}, 15500, (500, 1000)), ("cvae", {}, 7500, (7000, 7500))):
        (started / stage / "ckpt").mkdir(parents=True)
        (started / stage / "stage.json").write_text(json.dumps({"stage": stage, "upstream": upstream, "num_steps": total}))
        for step in ckpts:
            (started / stage / "ckpt" / str(step)).mkdir()
    (started / "dlow_k50" / "ckpt" / "1500.orbax-checkpoint-tmp").mkdir()  # a write a kill interrupted: not a checkpoint
    # Two training segments (time_s restarts at a resume); the pace is the newest one's median, 0.5 s a step
    # (one stretch of it paused for 600 s).
    log = [{"step": 50, "time_s": 10.0}, {"step": 100, "time_s": 90.0}, {"step": 500, "curve": True, "APD": 1.0},
           {"step": 1050, "time_s": 5.0}, {"step": 1100, "time_s": 30.0}, {"step": 1200, "time_s": 80.0},
           {"step": 1250, "time_s": 705.0}, {"step": 1300, "time_s": 730.0}]
    (started / "dlow_k50" / "log.jsonl").write_text("".join(json.dumps(r) + "\n" for r in log) + '{"step": 12')
    (runs / "dlow_humaneva_s0").mkdir()
    assert rh.main(["--results", str(tmp_path), "--runs-dir", str(runs), "--runs", "dlow_humaneva:0", "dlow_humaneva:1",
                    "gsps_humaneva:0", "--list"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "dlow_humaneva:0 (started: no checkpoint yet)",
        "dlow_humaneva:1 (started: cvae 7,500 / 7,500, dlow_k50 1,000 / 15,500 (0.50 s a step, about 2.0 h to go))",
        "gsps_humaneva:0",
    ]


def test_host_devices_go_to_the_named_configs_runs_only(tmp_path, monkeypatch, capsys):
    data, runs, results = tmp_path / "he.npz", tmp_path / "runs", tmp_path / "results"
    data.write_bytes(b"x")
    flags, real_run = {}, subprocess.run

    def fake(cmd, **kw):
        if "--workdir" not in cmd:
            return real_run(cmd, **kw)
        config = Path(cmd[cmd.index("--config") + 1]).stem
        flags[config] = cmd[cmd.index("--host-devices") + 1] if "--host-devices" in cmd else None
        _fake_run(Path(cmd[cmd.index("--workdir") + 1]), config, int(cmd[cmd.index("--seed") + 1]))
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(rh.subprocess, "run", fake)
    argv = ["--data", str(data), "--runs-dir", str(runs), "--results", str(results), "--runs", "dlow_humaneva:1",
            "mojo_vae_dct5_humaneva:0", "--host-devices", "2"]
    with pytest.raises(SystemExit):
        rh.main(argv + ["--host-devices-configs", "gsps_humaneva"])
    assert "--host-devices-configs: gsps_humaneva not among the runs to do" in capsys.readouterr().err
    assert rh.main(argv + ["--host-devices-configs", "mojo_vae_dct5_humaneva"]) == 0
    assert flags == {"dlow_humaneva": None, "mojo_vae_dct5_humaneva": "2"}


def test_snapshot_keeps_the_curves_of_unfinished_runs_only(tmp_path, capsys):
    runs, out = tmp_path / "runs", tmp_path / "partial"
    _fake_run(runs / "dlow_humaneva_s0", "dlow_humaneva", 0)  # finished: collected by the run itself, not here
    _fake_run(runs / "dlow_humaneva_s1", "dlow_humaneva", 1)
    (runs / "dlow_humaneva_s1" / "metrics.json").unlink()  # unfinished, with three curve points
    (runs / "mojo_vae_dct_humaneva_s0" / "cvae").mkdir(parents=True)  # started, no curve point yet
    argv = ["--results", str(tmp_path / "results"), "--runs-dir", str(runs), "--snapshot", str(out),
            "--runs", "dlow_humaneva:0", "dlow_humaneva:1", "mojo_vae_dct_humaneva:0", "gsps_humaneva:0"]
    assert rh.main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == ["dlow_humaneva_s1_partial_curve.json", "dlow_humaneva_s1_partial_curves.png"]
    rec = json.loads((out / "dlow_humaneva_s1_partial_curve.json").read_text())
    assert [p["step"] for p in rec["curve"]] == [0, 50, 100] and "unfinished: no checkpoint yet" in rec["run"]
    assert "dlow_humaneva_s1_partial_curve.json" in capsys.readouterr().out
    assert not (tmp_path / "results").exists()  # nothing trained, nothing collected
    assert rh.main([*argv[:5], str(tmp_path / "empty"), "--runs", "gsps_humaneva:0"]) == 0
    assert "no started, unfinished run" in capsys.readouterr().out
