"""`jaxmotion eval` walks the package downward: no module is called again from a module it called.

The walk is traced with `sys.setprofile` over one whole `jaxmotion eval` (CLI, data, restore,
every evaluator: protocol metrics with MotionMap's transferred references, mode recall, a
method's own metrics, CMD / FID). A "climb back" is a call into module A made, directly or
through other modules, by a module that A itself called: A -> B -> A on the call stack. The
action classifier behind FID is trained once per dataset and cached (the generic training loop
then calls its loss, a callback); the traced evaluation is one that finds it cached.
"""

from __future__ import annotations

import sys
import textwrap

from jaxmotion import cli

CONFIG = """
import dataclasses

from jaxmotion.config import Config
from jaxmotion.method import ExtraMetrics, Method, register
from jaxmotion.methods.common import zero_velocity
from jaxmotion.eval import realism


def extra(cfg, ds, params):
    return ExtraMetrics(lambda pred, gt: {"FSE": realism.fse(pred, gt)}, {"note": "walk"})


register(Method(name="walk_stub", config_type=dict, stages=lambda c, p: [],
                predictors=lambda c, ds, params, k: {"zero_velocity": zero_velocity(ds.t_pred, k)},
                extra_metrics=extra), replace=True)


def get_config():
    return Config(name="walk", method="walk_stub", method_config={}, eval_k=(2,), max_test_windows=24,
                  mm_ground_truth="motionmap-train", action_classifier_steps=5, eval_batch=8)
"""


def _module(frame) -> str:
    return frame.f_globals.get("__name__", "") or ""


def climbs_back(argv: list[str]) -> tuple[int, list[str]]:
    """Returns `(exit code, the distinct climb-back chains seen while running `jaxmotion argv`)`."""
    seen: dict[str, None] = {}

    def profile(frame, event, arg):
        if event != "call":
            return
        here = _module(frame)
        if not here.startswith("jaxmotion."):  # the package's modules (a config file's module is the user's)
            return
        chain, f = [here], frame.f_back
        while f is not None:
            m = _module(f)
            if m.startswith("jaxmotion.") and m != chain[-1]:
                chain.append(m)
            f = f.f_back
        if here in chain[1:]:  # `here` is below on the stack, with another module between
            cut = chain[: chain.index(here, 1) + 1]
            seen[" <- ".join(cut)] = None

    sys.setprofile(profile)
    try:
        code = cli.main(argv)
    finally:
        sys.setprofile(None)
    return code, list(seen)


def test_eval_walks_downward_only(tmp_path):
    path = tmp_path / "walk.py"
    path.write_text(textwrap.dedent(CONFIG))
    wd = tmp_path / "run"
    assert cli.main(["run", "--config", str(path), "--workdir", str(wd)]) == 0  # trains and caches the classifier
    (wd / "metrics.json").unlink()
    code, chains = climbs_back(["eval", "--config", str(path), "--workdir", str(wd)])
    assert code == 0 and (wd / "metrics.json").exists()
    assert chains == [], "modules called again from below:\n" + "\n".join(chains)


def test_the_tracer_sees_a_climb_back(tmp_path, monkeypatch):
    # The check can fail: a metric that calls back into the evaluation loop is reported.
    from jaxmotion.eval import loop
    from jaxmotion.eval import metrics

    real = metrics.WindowMetricStream.result

    def result(self):
        loop.format_record({"dataset": "d", "method": "m", "K": 1, "metrics": {}, "wall_s": 0.0})
        return real(self)

    monkeypatch.setattr(metrics.WindowMetricStream, "result", result)
    path = tmp_path / "walk.py"
    path.write_text(textwrap.dedent(CONFIG).replace('mm_ground_truth="motionmap-train", ', ""))
    wd = tmp_path / "run"
    assert cli.main(["train", "--config", str(path), "--workdir", str(wd)]) == 0
    code, chains = climbs_back(["eval", "--config", str(path), "--workdir", str(wd)])
    assert code == 0 and any(c.startswith("jaxmotion.eval.loop <- jaxmotion.") and "jaxmotion.eval.loop" in c.split(" <- ")[-1]
                             for c in chains), chains
