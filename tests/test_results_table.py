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


def _run(path: Path, name: str, mm: str, ade: float):
    path.mkdir(parents=True)
    rec = lambda method, a: {"K": 5, "method": method, "seed": 0, "mm_source": mm,  # noqa: E731
                             "config": {"name": name, "seed": 0}, "metrics": {"ADE": a, "MMADE": a + 0.1}}
    (path / "metrics.json").write_text(json.dumps([rec("zero_velocity", 0.43), rec("divsamp", ade)]))


def test_headline_keeps_runs_with_another_multimodal_ground_truth_in_their_own_table(tmp_path):
    _run(tmp_path / "a", "divsamp_long", "test", 0.22)
    _run(tmp_path / "b", "motionmap_long", "train", 0.27)
    text = _module().headline([str(tmp_path / "a"), str(tmp_path / "b")], ("ADE", "MMADE"))
    first, second = text.split("K = 5, MM ground truth: 'train'")
    assert first.startswith("K = 5\n") and "divsamp_long" in first and "motionmap_long" not in first
    assert "motionmap_long" in second and "divsamp_long" not in second
