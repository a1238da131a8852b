"""Learning curves (`Config.curve_every`): points in each stage's log, the frozen stage's curve constant, the plot."""

import importlib.util
import json
from pathlib import Path

import numpy as np

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
from jaxmotion import experiment as ex
from jaxmotion.config import Config
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig

ROOT = Path(__file__).resolve().parents[1]


def _curve_lines(stage_dir: Path) -> list[dict]:
    return [r for r in map(json.loads, (stage_dir / "log.jsonl").read_text().splitlines()) if r.get("curve")]


def test_curves_logged_per_stage_and_plotted(tmp_path, capsys):
    cfg = Config(action_metrics=False,
        method_config=DLowConfig(cvae=CVAEConfig(num_steps=30, batch_size=16, nz=8, nh_rnn=32, nh_mlp=(32,)),
                                 q=QConfig(num_steps=20, batch_size=8, nh_rnn=32, nh_mlp=(32,))), eval_k=(5,),
        curve_every=15, curve_windows=24, curve_k=5, max_test_windows=60, log_every=10,
    )
    prep = ex.prepare(ex.load_data(cfg), cfg.max_test_windows)
    ex.train(cfg, prep, tmp_path)
    cvae, q = _curve_lines(tmp_path / "cvae"), _curve_lines(tmp_path / "dlow_k5")
    assert [r["step"] for r in cvae] == [0, 15, 30]
    assert [r["step"] for r in q] == [0, 15, 20]
    assert all(r["n_windows"] == 24 and r["K"] == 5 for r in cvae + q)
    assert set(cvae[0]["predictors"]) == {"cvae"} and set(q[0]["predictors"]) == {"cvae", "dlow"}
    # The CVAE learns, and is frozen while the Q network trains: its curve there is its final point.
    assert cvae[-1]["predictors"]["cvae"]["ADE"] < cvae[0]["predictors"]["cvae"]["ADE"]
    for r in q:
        assert r["predictors"]["cvae"] == cvae[-1]["predictors"]["cvae"]
    assert q[-1]["predictors"]["dlow"] != q[0]["predictors"]["dlow"]
    vals = [v for r in cvae + q for m in r["predictors"].values() for v in m.values()]
    assert np.all(np.isfinite(vals))

    spec = importlib.util.spec_from_file_location("plot_curves", ROOT / "experiments" / "plot_curves.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main([str(tmp_path)]) == 0
    assert (tmp_path / "curves.png").stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "dlow_k5" in out and "last 20% of steps" in out
    assert mod.main([str(tmp_path / "cvae")]) == 1  # a folder without curve lines is reported, not drawn
    # --json-dir keeps every point, named by the run's config and seed.
    assert mod.main([str(tmp_path), "--out-dir", str(tmp_path / "png"), "--json-dir", str(tmp_path / "json"), "--about", "a test"]) == 0
    rec = json.loads((tmp_path / "json" / f"{cfg.name}_s{cfg.seed}_curve.json").read_text())
    assert rec["run"].endswith("a test")
    assert len(rec["curve"]) == sum(len(r["predictors"]) for r in cvae + q)
    last = [p for p in rec["curve"] if p["stage"] == "dlow_k5" and p["predictor"] == "dlow"][-1]
    assert last["step"] == 20 and last["ADE"] == q[-1]["predictors"]["dlow"]["ADE"]
    # A kept curve file reads back as the run's own curves, and is drawn beside another run in one figure.
    kept = tmp_path / "json" / f"{cfg.name}_s{cfg.seed}_curve.json"
    assert mod.load_curves(kept) == mod.load_curves(tmp_path)
    assert mod.main([str(kept), str(tmp_path), "--overlay", str(tmp_path / "both.png")]) == 0
    assert (tmp_path / "both.png").stat().st_size > 10_000
    assert not list((tmp_path / "json").glob("*.png"))  # nothing written beside a kept file
    bad = tmp_path / "bad_curve.json"
    bad.write_text('{"points": []}')
    assert mod.main([str(bad)]) == 1
    assert "bad_curve.json: not a learning-curve file (KeyError" in capsys.readouterr().err


def test_a_motionmap_run_has_no_curve_point_before_its_heatmap_stage():
    # MotionMap predicts only once its heatmap and codebook exist: during the autoencoder stage the
    # curve has no point: `predictors` offers only the (curve-skipped) zero-velocity baseline then.
    import jax
    import jax.numpy as jnp

    from jaxmotion.models import motionmap as mm
    from jaxmotion.models.motionmap import MotionMapConfig

    cfg = Config(method="motionmap", action_metrics=False, method_config=MotionMapConfig(hm_size=16),
                 eval_k=(5,), curve_every=10, curve_windows=8, curve_k=5, max_test_windows=20)
    ds = ex.load_data(cfg)
    prep = ex.prepare(ds, cfg.max_test_windows)
    c = cfg.method_config
    ae = mm.ae_model(c, ds.dim, ds.t_his, ds.t_pred)
    p = ae.init(jax.random.key(0), jnp.zeros((1, ds.t_his, ds.dim)), jnp.zeros((1, ds.t_pred, ds.dim)))
    from jaxmotion.eval import learning_curve
    from jaxmotion.methods import get_method

    method = get_method("motionmap")
    assert set(method.predictors(cfg, ds, {"autoencoder": p}, 5)) == {"zero_velocity"}
    assert learning_curve(cfg, method, prep)({"autoencoder": p}) is None
