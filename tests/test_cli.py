"""The `jaxmotion` command end to end on a tiny budget: run, resume, eval, sample."""

import json
from pathlib import Path

import pytest

from jaxmotion.cli import main
from jaxmotion.config import Config, load_config

REPO = Path(__file__).resolve().parents[1]

TINY = """
from jaxmotion.config import Config, CVAEConfig, DLowConfig
def get_config():
    return Config(name="tiny", cvae=CVAEConfig(num_steps=30, batch_size=16, nz=16, nh_rnn=32, nh_mlp=(32,)),
                  dlow=DLowConfig(num_steps=10, batch_size=4, nh_mlp=(32,)), eval_k=(6, 2),
                  ckpt_every=10, log_every=10, max_test_windows=40, eval_batch=16)
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    cfg = d / "tiny.py"
    cfg.write_text(TINY)
    assert main(["run", "--config", str(cfg), "--workdir", str(d / "work")]) == 0
    return cfg, d / "work"


def test_run_writes_protocol_records_and_picture(run_dir):
    cfg, work = run_dir
    records = json.loads((work / "metrics.json").read_text())
    assert {(r["method"], r["K"]) for r in records} == {(m, k) for m in ("zero_velocity", "cvae", "dlow") for k in (6, 2)}
    for r in records:
        # PROTOCOL sec. 5 fields.
        assert set(r) >= {"dataset", "method", "K", "n_windows", "metrics", "seed", "config", "jax_version", "device", "wall_s"}
        assert r["n_windows"] == 40
        assert set(r["metrics"]) >= {"APD", "ADE", "FDE", "MMADE", "MMFDE", "ADE-m", "FDE-m", "mode_recall"}
    zv = next(r for r in records if r["method"] == "zero_velocity")["metrics"]
    assert zv["APD"] == 0.0 and zv["ADE"] == zv["ADE-m"]
    png = work / "samples.png"
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    assert (work / "cvae" / "log.jsonl").exists() and (work / "dlow_k6" / "ckpt").is_dir()


def test_run_refuses_to_overwrite_then_resumes(run_dir):
    cfg, work = run_dir
    with pytest.raises(FileExistsError, match="--resume"):
        main(["train", "--config", str(cfg), "--workdir", str(work)])
    assert main(["train", "--config", str(cfg), "--workdir", str(work), "--resume"]) == 0


def test_eval_reproduces_run_metrics(run_dir):
    cfg, work = run_dir
    before = json.loads((work / "metrics.json").read_text())
    assert main(["eval", "--config", str(cfg), "--workdir", str(work)]) == 0
    after = json.loads((work / "metrics.json").read_text())
    for a, b in zip(before, after):
        assert a["metrics"]["ADE"] == pytest.approx(b["metrics"]["ADE"], rel=1e-5)


def test_sample_writes_npz_and_png(run_dir):
    import numpy as np

    cfg, work = run_dir
    assert main(["sample", "--config", str(cfg), "--workdir", str(work), "--window", "3", "--k", "6"]) == 0
    z = np.load(work / "sample_w3_dlow_k6.npz")
    assert z["preds"].shape == (6, 60, 48) and z["x"].shape == (15, 48)
    with pytest.raises(SystemExit, match="trained for K in"):
        main(["sample", "--config", str(cfg), "--workdir", str(work), "--k", "7"])


def test_default_config_is_the_synthetic_config_file():
    assert load_config(REPO / "experiments" / "configs" / "dlow_synthetic.py") == Config()


def test_bad_config_path_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="config file not found"):
        load_config(tmp_path / "nope.py")
    bad = tmp_path / "bad.py"
    bad.write_text("x = 1\n")
    with pytest.raises(ValueError, match="get_config"):
        load_config(bad)
