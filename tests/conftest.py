"""Fixtures shared by several test modules: one tiny trained DLow run per session (tests/test_cli.py, tests/test_viewer.py)."""

import pytest

# DLow on the synthetic data on a tiny budget: trains, evaluates and reports in seconds.
TINY = """
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig
def get_config():
    return Config(name="tiny", method_config=DLowConfig(
                      cvae=CVAEConfig(num_steps=30, batch_size=16, nz=16, nh_rnn=32, nh_mlp=(32,)),
                      q=QConfig(num_steps=10, batch_size=4, nh_mlp=(32,))),
                  eval_k=(6, 2), ckpt_every=10, log_every=10, max_test_windows=40, eval_batch=16)
"""


@pytest.fixture(scope="session")
def tiny_cli_run(tmp_path_factory):
    """Returns `(config file, work directory)` of `jaxmotion run` with the TINY config (trained once per session).

    Tests may add files to the work directory (or re-evaluate it) but must not remove or corrupt what the run wrote.
    """
    from jaxmotion.cli import main

    d = tmp_path_factory.mktemp("cli")
    cfg = d / "tiny.py"
    cfg.write_text(TINY)
    assert main(["run", "--config", str(cfg), "--workdir", str(d / "work")]) == 0
    return cfg, d / "work"
