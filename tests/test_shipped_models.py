"""The shipped models' registry and cards are generated from the measured results, and the default was chosen by its rule."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("shipped_models", ROOT / "experiments" / "shipped_models.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_registry_and_cards_are_generated_from_the_results_and_the_default_follows_the_rule():
    mod = _script()
    results = json.loads(mod.RESULTS.read_text())
    reg, readme = mod.ship(results)
    assert json.loads((ROOT / "jaxmotion" / "pretrained" / "models.json").read_text()) == reg
    assert (ROOT / "jaxmotion" / "pretrained" / "README.md").read_text() == readme
    # The default has the lowest validation ADE; the test windows chose nothing.
    val = {m["name"]: m["metrics"]["validation"]["ADE"] for m in reg["models"]}
    assert reg["default"] == min(val, key=val.get) and "validation" in reg["rule"]
    assert len(reg["models"]) >= 1 and all((ROOT / "jaxmotion" / "pretrained" / m["file"]).is_file() for m in reg["models"])
