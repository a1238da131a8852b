"""Your own motion: a run as a self-contained predictor, `jaxmotion predict`, BVH writing, GIFs, plain BVH folders."""

import dataclasses
import itertools
import json
import shutil
from pathlib import Path

import jax
import numpy as np
import pytest
from PIL import Image

# CMD and FID are off in this file's configs (`action_metrics=False`): tests/test_action_metrics.py covers them.
import jaxmotion
from jaxmotion import experiment
from jaxmotion.cli import main
from jaxmotion.config import Config, to_dict
from jaxmotion.data.folder_split import folder_split
from jaxmotion.data.synthetic import make_synthetic
from jaxmotion.errors import CheckpointError, DataError
from jaxmotion.formats.bvh import euler_matrices, forward_kinematics, read_bvh
from jaxmotion.formats.bvh_write import matrix_to_euler, read_end_sites, write_bvh
from jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig
from jaxmotion.tools.predict_file import predict_file
from jaxmotion.tools.predictor import config_from_dict
from jaxmotion.tools.retarget import bvh_from_positions, fit_bvh

CMU = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu-bvh"

TINY = Config(action_metrics=False,
    name="tiny_predict",
    method_config=DLowConfig(cvae=CVAEConfig(num_steps=20, batch_size=8, nz=8, nh_rnn=16, nh_mlp=(16,)),
                             q=QConfig(num_steps=4, batch_size=4, nh_rnn=16, nh_mlp=(16,))),
    eval_k=(4,), ckpt_every=50, log_every=50, max_test_windows=8, eval_batch=8,
)  # fmt: skip


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny DLow run trained on synthetic data, then moved: nothing of its training data is reachable."""
    d = tmp_path_factory.mktemp("predict")
    cfg = experiment.resolve(TINY)
    ds = make_synthetic(0, train_sequences=2, train_segments=4, test_sequences=1, test_segments=4)
    prep = experiment.prepare(ds, cfg.max_test_windows)
    params = experiment.train(cfg, prep, d / "work")
    moved = d / "moved"
    shutil.move(d / "work", moved)
    return cfg, ds, prep, params, moved


def synthetic_clip(ds, path: Path, fps_factor: int = 1) -> Path:
    """Writes a synthetic test sequence as a BVH (the synthetic data's own BVH export) and returns the path."""
    pos = ds.test[0].positions
    if fps_factor > 1:  # a higher frame rate: every frame, then the midpoints
        mid = (pos[1:] + pos[:-1]) / 2
        pos = np.stack([pos[:-1], mid], axis=1).reshape(-1, *pos.shape[1:])
    return write_bvh(path, bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, pos, ds.fps * fps_factor))


def test_euler_decomposition_inverts_bvh_rotations_in_every_order():
    rng = np.random.default_rng(0)
    for axes in map("".join, itertools.permutations("XYZ")):
        e = rng.uniform(-179, 179, (200, 3))
        e[:, 1] = rng.uniform(-89, 89, 200)
        np.testing.assert_allclose(matrix_to_euler(euler_matrices(e, axes), axes), e, atol=1e-8)
        e[:, 1] = 90.0 * rng.choice([-1, 1], 200)  # gimbal lock: the matrix is still reproduced
        r = euler_matrices(e, axes)
        np.testing.assert_allclose(euler_matrices(matrix_to_euler(r, axes), axes), r, atol=1e-9)


def test_positions_to_bvh_to_forward_kinematics_round_trip(tmp_path):
    """Predicted positions -> BVH on a skeleton -> the project's reader and FK -> the same positions (< 1 cm; here ~1e-6 m)."""
    ds = make_synthetic(0, train_sequences=1, train_segments=2, test_sequences=1, test_segments=2)
    pos = ds.test[0].positions[:90].astype(np.float64)
    src = write_bvh(tmp_path / "src.bvh", bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, pos[:5], ds.fps))
    bvh = read_bvh(src)
    # Targets with the skeleton's bone lengths (the synthetic subject is rigid), its reference the first frame.
    fitted = fit_bvh(bvh, pos, np.ones(bvh.num_joints, bool), reference_frame=0)
    back = read_bvh(write_bvh(tmp_path / "out.bvh", fitted, read_end_sites(src)))
    assert back.names == bvh.names and back.parents == bvh.parents
    err = np.linalg.norm(forward_kinematics(back) - pos, axis=-1)
    assert err.max() < 0.01 and err.max() < 1e-4


def test_fit_keeps_bone_directions_when_lengths_differ():
    ds = make_synthetic(0, train_sequences=1, train_segments=2, test_sequences=1, test_segments=2)
    pos = ds.test[0].positions[:20].astype(np.float64)
    bvh = bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, pos[:1], ds.fps)
    par = np.array(ds.skeleton.parents)
    stretched = pos.copy()
    for j in range(1, len(par)):  # every bone 20% longer
        stretched[:, j] = stretched[:, par[j]] + 1.2 * (pos[:, j] - pos[:, par[j]])
    got = forward_kinematics(fit_bvh(bvh, stretched, np.ones(len(par), bool)))
    d_want = stretched[:, 1:] - stretched[:, par[1:]]
    d_got = got[:, 1:] - got[:, par[1:]]
    cos = np.sum(d_want * d_got, -1) / np.linalg.norm(d_want, axis=-1) / np.linalg.norm(d_got, axis=-1)
    assert cos.min() > 1 - 1e-9
    rest = np.linalg.norm(pos[0, 1:] - pos[0, par[1:]], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(d_got, axis=-1), np.broadcast_to(rest, d_got.shape[:2]), rtol=1e-9)


def test_config_survives_predictor_json():
    cfg = experiment.resolve(TINY)
    assert config_from_dict(json.loads(json.dumps(to_dict(cfg)))) == cfg


def test_load_predicts_like_the_training_job_without_its_data(run, monkeypatch):
    cfg, ds, prep, params, moved = run
    monkeypatch.setattr(experiment, "load_data", lambda *a, **k: pytest.fail("load touched the data"))
    monkeypatch.setattr("jaxmotion.data.synthetic.make_synthetic", lambda *a, **k: pytest.fail("load touched the data"))
    model = jaxmotion.load(moved)
    assert model.methods == ["cvae", "dlow", "zero_velocity"]
    lay = json.loads((moved / "predictor.json").read_text())["layout"]
    assert lay["joints"] == list(ds.skeleton.names) and (lay["t_his"], lay["t_pred"], lay["fps"]) == (15, 60, 30.0)
    key = jax.random.key(3)
    got = model.predict(prep.x[:2], 4, key)
    want = np.asarray(experiment.predictors(cfg, ds, params, 4)["dlow"](prep.x[:2], key))
    assert got.shape == (2, 4, 60, ds.dim)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    one = model.predict(prep.x[0], 4, key, method="cvae")
    assert one.shape == (4, 60, ds.dim) and np.ptp(one, axis=0).max() > 0
    with pytest.raises(ValueError, match="not available"):
        model.predict(prep.x[0], 3, key, method="dlow")  # DLow was trained for K = 4 only
    with pytest.raises(ValueError, match=r"t_his=15"):
        model.predict(prep.x[0, :10], 4, key)


def test_predict_command_on_a_bvh_clip(run, tmp_path, capsys):
    _, ds, _, _, moved = run
    clip = synthetic_clip(ds, tmp_path / "clip.bvh", fps_factor=2)  # 60 fps: resampled to the model's 30
    assert main(["predict", str(moved), "--input", str(clip), "--k", "3", "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "resampled from 60 to 30 fps" in printed and "wrote" in printed
    z = np.load(tmp_path / "out" / "futures.npz")
    assert z["futures"].shape == (3, 60, ds.dim) and z["ground_truth"].shape == (60, ds.dim)
    src = read_bvh(clip)
    for i in range(3):
        b = read_bvh(tmp_path / "out" / f"future_{i:02d}.bvh")
        assert b.names == src.names and b.num_frames == 15 + 60 and abs(b.fps - 30) < 1e-6
        p = forward_kinematics(b)
        # The BVH moves the input's own skeleton: its bone lengths, the predicted bone directions.
        par = np.array(b.parents)
        d_bvh = p[15:, 1:] - p[15:, par[1:]]
        fut = z["joints"][i]
        d_pred = fut[:, 1:] - fut[:, par[1:]]
        cos = np.sum(d_bvh * d_pred, -1) / np.linalg.norm(d_bvh, axis=-1) / np.linalg.norm(d_pred, axis=-1)
        assert np.median(cos) > 0.999
        np.testing.assert_allclose(np.linalg.norm(d_bvh, axis=-1), np.linalg.norm(src.offsets[1:], axis=-1)[None].repeat(60, 0), rtol=1e-4)
    gif = Image.open(tmp_path / "out" / "samples.gif")
    assert gif.n_frames > 10


def test_predict_names_missing_and_extra_joints(run, tmp_path, capsys):
    _, ds, _, _, moved = run
    clip = synthetic_clip(ds, tmp_path / "clip.bvh")
    text = clip.read_text().replace("JOINT LWrist", "JOINT LeftHand")
    bad = tmp_path / "renamed.bvh"
    bad.write_text(text)
    with pytest.raises(DataError, match=r"missing joints \['LWrist'\]; extra joints \['LeftHand'\]"):
        predict_file(jaxmotion.load(moved), bad, tmp_path / "o")
    assert main(["predict", str(moved), "--input", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "missing joints ['LWrist']" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_predict_from_npz_positions(run, tmp_path):
    _, ds, _, _, moved = run
    pos = ds.test[0].positions[:40]  # shorter than t_his + t_pred: the window ends at the last frame
    np.savez(tmp_path / "clip.npz", positions=pos * 100, scale=0.01, names=np.array(ds.skeleton.names), fps=30.0)
    assert main(["predict", str(moved), "--input", str(tmp_path / "clip.npz"), "--k", "2", "--out", str(tmp_path / "o"), "--method", "cvae"]) == 0
    z = np.load(tmp_path / "o" / "futures.npz")
    assert int(z["end_frame"]) == 39 and z["ground_truth"].shape[0] == 0
    np.testing.assert_allclose(z["observed"][-1], (pos[39, 1:] - pos[39, :1]).ravel(), atol=1e-5)
    b = read_bvh(tmp_path / "o" / "future_01.bvh")
    np.testing.assert_allclose(forward_kinematics(b)[14] * 0.01, pos[39], atol=1e-5)  # the last observed frame, in cm


def test_an_up_axis_the_model_cannot_honour_is_refused(run, tmp_path, capsys):
    """The synthetic run records no up axis: an npz that declares one is refused, not predicted in the wrong axes."""
    _, ds, _, _, moved = run
    np.savez(tmp_path / "clip.npz", positions=ds.test[0].positions[:40], names=np.array(ds.skeleton.names), up_axis=2)
    assert main(["predict", str(moved), "--input", str(tmp_path / "clip.npz"), "--out", str(tmp_path / "o")]) == 2
    assert "clip.npz: 'up_axis' is z, but the model records no up axis" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_an_empty_out_is_refused_not_the_current_folder(run, tmp_path, monkeypatch, capsys):
    _, ds, _, _, moved = run
    np.savez(tmp_path / "clip.npz", positions=ds.test[0].positions[:40], names=np.array(ds.skeleton.names))
    monkeypatch.chdir(tmp_path)
    assert main(["predict", str(moved), "--input", "clip.npz", "--out", ""]) == 2
    assert "--out is empty; give the folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.npz"]


def test_folder_split_by_subject_by_file_and_by_pattern(tmp_path):
    for name in ["01_01", "01_02", "02_01", "03_01", "03_02"]:
        (tmp_path / f"{name}.bvh").write_text("")
    split, how = folder_split(tmp_path)
    assert {f.stem for f, s in split.items() if s == "test"} == {"03_01", "03_02"} and "subject" in how
    split, _ = folder_split(tmp_path, ["02_*"])
    assert {f.stem for f, s in split.items() if s == "test"} == {"02_01"}
    with pytest.raises(DataError, match="matches none"):
        folder_split(tmp_path, ["99_*"])
    other = tmp_path / "one_subject"
    other.mkdir()
    for name in ["walk", "run", "jump"]:
        (other / f"{name}.bvh").write_text("")
    split, how = folder_split(other)
    assert [f.stem for f, s in split.items() if s == "test"] == ["walk"] and "last 1 of 3" in how


def test_folder_without_a_fitting_window_says_why(tmp_path):
    ds = make_synthetic(0, train_sequences=1, train_segments=2, test_sequences=1, test_segments=2)
    for i, s in enumerate(ds.test[:1] + ds.train[:1]):
        write_bvh(tmp_path / f"{i:02d}_01.bvh", bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, s.positions[:50], 30.0))
    d = experiment.load_data(Config(), str(tmp_path))
    assert len(d.train) == 1 and len(d.test) == 1
    with pytest.raises(DataError, match=r"1 training sequences \(longest 50 frames\).*t_his \+ t_pred = 15 \+ 60 = 75 frames at 30 fps"):
        experiment.prepare(d)


@pytest.mark.skipif(not CMU.is_dir(), reason=f"shared CMU BVH clips not found at {CMU}")
def test_cmu_folder_splits_by_file_and_loads_at_a_lower_rate():
    d = experiment.load_data(dataclasses.replace(Config(), data_options={"downsample": 4}), str(CMU))
    assert [s.name for s in d.train] == ["01_01.bvh"] and [s.name for s in d.test] == ["01_03.bvh"]
    assert (d.fps, d.t_his, d.t_pred) == (30.0, 15, 60)
    prep = experiment.prepare(d)
    assert prep.sampler.num_windows == 688 - 75 + 1


def test_report_writes_an_animated_gif(run, tmp_path):
    cfg, _, prep, params, _ = run
    png = experiment.report(cfg, prep, params, tmp_path)
    gif = Image.open(tmp_path / "samples.gif")
    # Observed (15) then future (60) frames, subsampled to at most 30 (+ the last); truth and the first futures side by side.
    assert png.name == "samples.png" and 20 <= gif.n_frames <= 31
    assert gif.size[0] > 4 * gif.size[1] and gif.size[0] >= 1200
    first, last = np.asarray(gif.convert("RGB")), (gif.seek(gif.n_frames - 1), np.asarray(gif.convert("RGB")))[1]
    assert np.abs(first.astype(int) - last.astype(int)).sum() > 0  # it moves


def _with_position_channels_everywhere(bvh):
    """Returns `bvh` with 6 channels on every joint, the position ones holding the offsets (Bandai-Namco-2's layout)."""
    chans = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    cols = []
    for j, (c, s) in enumerate(zip(bvh.channels, bvh.channel_starts)):
        rot = {n: bvh.motion[:, s + k] for k, n in enumerate(c) if "rotation" in n}
        pos = bvh.motion[:, s : s + 3] if "Xposition" in c else np.broadcast_to(bvh.offsets[j], (bvh.num_frames, 3))
        cols += [pos, np.stack([rot["Zrotation"], rot["Xrotation"], rot["Yrotation"]], axis=1)]
    return dataclasses.replace(bvh, channels=(chans,) * bvh.num_joints, motion=np.concatenate(cols, axis=1))


def test_fit_moves_only_the_top_joint_when_every_joint_has_position_channels():
    ds = make_synthetic(0, train_sequences=1, train_segments=2, test_sequences=1, test_segments=2)
    pos = ds.test[0].positions[:30].astype(np.float64)
    ref = bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, pos, ds.fps, order="ZXY")
    six = _with_position_channels_everywhere(ref)
    np.testing.assert_allclose(forward_kinematics(six), forward_kinematics(ref), atol=1e-12)
    fitted = fit_bvh(six, pos, np.ones(len(pos[0]), bool), reference_frame=0)
    np.testing.assert_allclose(forward_kinematics(fitted), pos, atol=1e-6)
    # Below the root the position channels keep the offsets: the pose is carried by rotations.
    for j in range(1, six.num_joints):
        s = six.channel_starts[j]
        np.testing.assert_allclose(fitted.motion[:, s : s + 3], np.broadcast_to(six.offsets[j], (30, 3)), atol=1e-12)


@pytest.mark.skipif(not CMU.is_dir(), reason=f"shared CMU BVH clips not found at {CMU}")
def test_cmu_clip_round_trips_through_the_writer(tmp_path):
    """CMU's skeleton has zero-length bones (LHipJoint) and joints with three children: still exact."""
    bvh = read_bvh(CMU / "01_01.bvh")
    pos = forward_kinematics(bvh, slice(500, 560))
    fitted = fit_bvh(bvh, pos, np.ones(bvh.num_joints, bool), reference_frame=0)
    back = read_bvh(write_bvh(tmp_path / "rt.bvh", fitted, read_end_sites(bvh.path)))
    assert back.names == bvh.names and back.parents == bvh.parents
    assert np.abs(forward_kinematics(back) - pos).max() * 0.056444 < 1e-4


def test_load_restores_only_the_stages_asked_for(run, tmp_path):
    """A run stopped before its last stage wrote a checkpoint still gives its earlier stages (validity_table's GSPS prior)."""
    cfg, ds, prep, params, moved = run
    first, last = list(params)[0], list(params)[-1]
    part = tmp_path / "partial"
    shutil.copytree(moved, part)
    shutil.rmtree(part / last / "ckpt")
    (part / last / "ckpt").mkdir()  # the stage began, no checkpoint yet
    got = jaxmotion.load(part, stages=(first,))
    assert list(got.params) == [first]
    for a, b in zip(jax.tree.leaves(got.params[first]), jax.tree.leaves(params[first]), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(CheckpointError, match="no checkpoint"):
        jaxmotion.load(part)
    with pytest.raises(CheckpointError, match=f"{last}/ckpt: no checkpoint"):
        jaxmotion.load(part, stages=(first, last))
    with pytest.raises(CheckpointError, match=r"\['nope'\] not trained"):
        jaxmotion.load(part, stages=(first, "nope"))


def test_predicted_bvh_npz_and_gif_show_one_motion_on_the_input_skeleton(run, tmp_path):
    """The futures are put on the input's bone lengths: BVH forward kinematics == futures.npz within 1 mm; raw output kept."""
    _, ds, _, _, moved = run
    pos = ds.test[0].positions.astype(np.float64) * 100  # centimetres
    pos[:, 1:] += 0.3 * (pos[:, 1:] - pos[:, [0]])  # a body 1.3 x the model's: its bone lengths differ from the training data's
    clip = write_bvh(tmp_path / "big.bvh", bvh_from_positions(ds.skeleton.names, ds.skeleton.parents, pos, ds.fps))
    lines = predict_file(jaxmotion.load(moved), clip, tmp_path / "o", k=3)
    assert any("futures fitted to the input's skeleton" in s for s in lines)
    z = np.load(tmp_path / "o" / "futures.npz")
    src = read_bvh(clip)
    par = np.array(src.parents)
    want = np.linalg.norm(src.offsets[1:], axis=-1) * 0.01
    for i in range(3):
        p = forward_kinematics(read_bvh(tmp_path / "o" / f"future_{i:02d}.bvh")) * 0.01
        assert np.abs(p[15:] - z["joints"][i]).max() < 1e-3
        assert np.abs(p[:15] - z["observed_joints"]).max() < 1e-3
        np.testing.assert_allclose(np.linalg.norm(p[:, 1:] - p[:, par[1:]], axis=-1), np.broadcast_to(want, (75, len(want))), rtol=1e-5)
        np.testing.assert_allclose(z["futures"][i], (z["joints"][i][:, 1:] - z["joints"][i][:, :1]).reshape(60, -1), atol=1e-5)
    # The model's output stays beside it, already on the input's bones (retargeted back from the model's skeleton);
    # with --no-retarget it is on the training data's, another body.
    raw = z["joints_raw"]
    assert raw.shape == (3, 60, ds.skeleton.num_joints, 3)
    np.testing.assert_allclose(np.linalg.norm(raw[:, :, 1:] - raw[:, :, par[1:]], axis=-1), np.broadcast_to(want, (3, 60, len(want))), rtol=1e-4)
    predict_file(jaxmotion.load(moved), clip, tmp_path / "n", k=3, retarget=False)
    raw = np.load(tmp_path / "n" / "futures.npz")["joints_raw"]
    assert np.abs(np.linalg.norm(raw[:, :, 1:] - raw[:, :, par[1:]], axis=-1) - want).max() > 0.05


def test_exported_model_predicts_like_its_run(run, tmp_path, capsys):
    _, ds, prep, _, moved = run
    assert main(["export", str(moved), "--out", str(tmp_path / "m.msgpack")]) == 0
    from_dir, from_file = jaxmotion.load(moved), jaxmotion.load(tmp_path / "m.msgpack")
    assert from_file.methods == from_dir.methods and from_file.layout == from_dir.layout
    key = jax.random.key(3)
    for m in from_dir.methods:
        np.testing.assert_array_equal(from_file.predict(prep.x[:2], 4, key, m), from_dir.predict(prep.x[:2], 4, key, m))
    # No optimiser state: the file is about the size of the parameters.
    n = sum(v.size for p in from_dir.params.values() for v in jax.tree.leaves(p))
    assert (tmp_path / "m.msgpack").stat().st_size < 4 * n * 1.05 + 20_000
    clip = synthetic_clip(ds, tmp_path / "clip.bvh")
    assert main(["predict", "--model", str(tmp_path / "m.msgpack"), str(clip), "--k", "2", "--out", str(tmp_path / "o")]) == 0
    bad = tmp_path / "bad.msgpack"
    bad.write_bytes((tmp_path / "m.msgpack").read_bytes()[:5000])
    with pytest.raises(CheckpointError, match="not an exported jaxmotion model"):
        jaxmotion.load(bad)


def test_float16_export_is_half_the_size_and_predicts_alike(run, tmp_path):
    _, _, prep, _, moved = run
    assert main(["export", str(moved), "--out", str(tmp_path / "m32.msgpack")]) == 0
    assert main(["export", str(moved), "--out", str(tmp_path / "m16.msgpack"), "--float16"]) == 0
    s32, s16 = (tmp_path / "m32.msgpack").stat().st_size, (tmp_path / "m16.msgpack").stat().st_size
    assert s16 < 0.6 * s32
    a, b = jaxmotion.load(tmp_path / "m32.msgpack"), jaxmotion.load(tmp_path / "m16.msgpack")
    assert all(v.dtype == np.float32 for p in b.params.values() for v in jax.tree.leaves(p) if np.issubdtype(v.dtype, np.floating))
    key = jax.random.key(1)
    got, want = b.predict(prep.x[:2], 4, key, "cvae"), a.predict(prep.x[:2], 4, key, "cvae")
    assert 0 < np.abs(got - want).max() < 1e-2  # rounded weights: close, not equal


def test_models_command_lists_every_shipped_model(capsys):
    from jaxmotion.tools.predictor import PRETRAINED, shipped_models

    assert main(["models"]) == 0
    out = capsys.readouterr().out
    reg = shipped_models()
    for m in reg["models"]:
        assert any(line.startswith(m["name"] + " ") for line in out.splitlines())
        assert (Path(jaxmotion.__file__).parent / "pretrained" / m["file"]).is_file()
    assert f"default: {reg['default']}, chosen by {reg['rule']}" in out and PRETRAINED["bandai"] == PRETRAINED[reg["default"]]
    assert "licence: CC BY-NC 4.0" in out
