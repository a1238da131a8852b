"""experiments/results_table.py: the training wall time of a run, resumed runs included."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("results_table", ROOT / "experiments" / "results_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _log(path: Path, times: list[float]):
    path.mkdir(parents=True)
    lines = [json.dumps({"step": 100 * i, "time_s": t}) for i, t in enumerate(times)]
    lines.insert(1, json.dumps({"step": 0, "curve": True, "eval_s": 3.0}))  # curve records carry no time_s
    (path / "log.jsonl").write_text("\n".join(lines) + "\n")


def test_train_minutes_adds_the_time_of_a_process_that_was_resumed(tmp_path):
    _log(tmp_path / "cvae", [10.0, 60.0, 120.0])  # one process: 120 s
    _log(tmp_path / "heatmap", [5.0, 300.0, 600.0, 20.0, 240.0])  # stopped at 600 s, resumed: 240 s more
    assert abs(_module().train_minutes(tmp_path) - (120.0 + 600.0 + 240.0) / 60) < 1e-9


def test_train_minutes_is_none_without_logs(tmp_path):
    assert _module().train_minutes(tmp_path) is None
