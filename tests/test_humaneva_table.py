"""The HumanEva-I table's verdict rule: ADE and FDE within 5% of the paper's, or the paper's inside our seeds' range."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("docs_generate", ROOT / "docs" / "generate.py")
generate = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(generate)

PAPER = {"ADE": 0.250, "FDE": 0.270}


def test_within_five_percent_is_reproduced():
    ok, why = generate.humaneva_verdict(PAPER, [{"ADE": 0.260, "FDE": 0.260}])
    assert ok and "ADE +4.0%" in why and "FDE -3.7%" in why


def test_one_metric_off_by_more_is_not_reproduced():
    ok, why = generate.humaneva_verdict(PAPER, [{"ADE": 0.250, "FDE": 0.300}])
    assert not ok and "FDE +11.1%" in why


def test_the_paper_inside_the_seeds_range_is_reproduced():
    seeds = [{"ADE": 0.220, "FDE": 0.270}, {"ADE": 0.300, "FDE": 0.270}]  # mean 0.26: +4%, and inside
    assert generate.humaneva_verdict(PAPER, seeds)[0]
    wide = [{"ADE": 0.230, "FDE": 0.270}, {"ADE": 0.330, "FDE": 0.270}]  # mean 0.28 (+12%), 0.25 inside
    ok, why = generate.humaneva_verdict(PAPER, wide)
    assert ok and "inside the seeds' range" in why
    # One seed has no range: the same +12% is not reproduced.
    assert not generate.humaneva_verdict(PAPER, [{"ADE": 0.280, "FDE": 0.270}])[0]


def test_every_paper_row_names_a_committed_config():
    for label, _source, nums, config, _predictor in generate.HUMANEVA_ROWS:
        assert len(nums) == len(generate.HE_METRICS), label
        assert (ROOT / "experiments" / "configs" / f"{config}.py").exists(), f"{label}: {config}.py is not committed"


def test_a_budget_reduced_config_stands_in_only_without_a_release_run(tmp_path, monkeypatch):
    monkeypatch.setattr(generate, "EXP", tmp_path)
    (tmp_path / generate.HUMANEVA).mkdir()
    full, part = "gsps_humaneva", generate.HUMANEVA_PARTIAL["gsps_humaneva"][0]
    assert generate.humaneva_runs(full) == []
    (tmp_path / generate.HUMANEVA / f"{part}_s1_metrics.json").write_text("[]")
    (tmp_path / generate.HUMANEVA / f"{part}_s0_metrics.json").write_text("[]")
    assert generate.humaneva_runs(full) == [f"{generate.HUMANEVA}/{part}_s0_metrics.json",
                                            f"{generate.HUMANEVA}/{part}_s1_metrics.json"]
    (tmp_path / generate.HUMANEVA / f"{full}_s0_metrics.json").write_text("[]")
    assert generate.humaneva_runs(full) == [f"{generate.HUMANEVA}/{full}_s0_metrics.json"]
    assert generate._release_config(part) == full and generate._release_config(full) == full


def test_every_stand_in_config_is_committed_with_fewer_steps():
    from jaxmotion.config import load_config, to_dict

    for full, parts in generate.HUMANEVA_PARTIAL.items():
        release = generate._flat_steps(to_dict(load_config(ROOT / "experiments" / "configs" / f"{full}.py")))
        for part in parts:
            steps = generate._flat_steps(to_dict(load_config(ROOT / "experiments" / "configs" / f"{part}.py")))
            assert steps.keys() == release.keys() and all(steps[k] <= release[k] for k in steps), part
            assert any(steps[k] < release[k] for k in steps), f"{part} runs the release's whole budget"


def test_the_figure_has_every_published_row_once_and_ours_only_where_run(tmp_path, monkeypatch):
    monkeypatch.setattr(generate, "EXP", tmp_path)
    (tmp_path / generate.HUMANEVA).mkdir()
    rec = [{"method": "dlow", "K": 50, "seed": 0, "config": {"name": "dlow_humaneva"},
            "metrics": {"APD": 4.9, "ADE": 0.245, "FDE": 0.27, "MMADE": 0.36, "MMFDE": 0.35}}]
    (tmp_path / generate.HUMANEVA / "dlow_humaneva_s0_metrics.json").write_text(json.dumps(rec))
    points = generate.humaneva_points()
    # DLow's row appears once (its own paper's), though two papers print it.
    assert [p[0] for p in points] == list(dict.fromkeys(r[0] for r in generate.HUMANEVA_ROWS))
    dlow = points[0]
    assert dlow[1]["ADE"] == 0.251 and dlow[2]["ADE"] == 0.245 and dlow[2]["APD"] == 4.9
    assert all(ours is None for _, _, ours in points[1:])
