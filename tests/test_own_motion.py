"""Any humanoid BVH in: per-file units and frame rates, joint maps and hierarchy checks, the shipped model, eval on a folder."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

import jaxmotion
from jaxmotion.cli import main
from jaxmotion.data.datasets import load_bvh_folder
from jaxmotion.data.units import PLAUSIBLE_SIZE, parse_scale
from jaxmotion.errors import DataError
from jaxmotion.formats.bvh import forward_kinematics, read_bvh
from jaxmotion.tools.joint_maps import CONVENTIONS, conventions_of, match_skeleton
from jaxmotion.tools.predict_file import predict_file

from humanoid_bvh import humanoid_bvh

CMU = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu-bvh"
BANDAI = CONVENTIONS["bandai"]
BANDAI_NAMES = [BANDAI[r] for r in ("pelvis", "spine", "chest", "neck", "head")] + [
    BANDAI[f"{s}_{r}"] for s in "lr" for r in ("clavicle", "upperarm", "forearm", "hand")
] + [BANDAI[f"{s}_{r}"] for s in "lr" for r in ("thigh", "shin", "foot", "toe")]


def _sizes(ds) -> np.ndarray:
    """Returns every sequence's body size in metres (largest joint distance, median over frames)."""
    out = []
    for s in ds.train + ds.test:
        p = s.positions[:: max(1, len(s.positions) // 8)]
        out.append(np.median(np.linalg.norm(p[:, :, None] - p[:, None], axis=-1).max(axis=(1, 2))))
    return np.asarray(out)


# ----------------------------------------------------------------------------------------------
# Units and frame rates per file


def test_folder_in_two_unit_systems_is_one_error_listing_every_file(tmp_path):
    humanoid_bvh("bandai", tmp_path / "a_walk.bvh", unit=0.01, seed=0)
    humanoid_bvh("bandai", tmp_path / "b_walk.bvh", unit=0.056444, seed=1)  # CMU/ASF units: a 29-unit body
    humanoid_bvh("bandai", tmp_path / "c_walk.bvh", unit=0.01, seed=2)
    with pytest.raises(DataError) as e:
        load_bvh_folder(tmp_path)
    msg = str(e.value)
    assert "1 of 3 files have no unit" in msg
    for name in ("a_walk.bvh", "b_walk.bvh", "c_walk.bvh"):
        assert name in msg
    assert re.search(r"a_walk.bvh: 1\d\d file units x 0.01 m \(guessed\) = 1\.\d\d m\n", msg)
    assert re.search(r"b_walk.bvh: [23]\d\.\d\d file units, no unit guessed; would fit: .*CMU/ASF unit \(0.056444: 1\.\d\d m\)", msg)
    assert "--scale 'PATTERN=NUMBER'" in msg
    # Per-file scales: every body a person's, and training sees the skeleton's own bone lengths (thigh 0.42 m).
    assert main(["train", "--config", str(_tiny_config(tmp_path)), "--data", str(tmp_path), "--scale", "b_*=0.056444",
                 "--test-files", "c_*", "--workdir", str(tmp_path / "w")]) == 0
    m = json.loads((tmp_path / "w" / "predictor.json").read_text())
    assert m["bone_lengths"][m["layout"]["joints"].index("LowerLeg_L")] == pytest.approx(0.42, abs=1e-4)
    sizes = _sizes(load_bvh_folder(tmp_path, scale={"b_*": 0.056444}))
    assert np.all((sizes > 1.4) & (sizes < 2.0)), sizes
    # A wrong scale given for every file is caught too: never a silent 0.25 m body.
    with pytest.raises(DataError, match=r"\(given\) = 0\.16 m \(not a person\)"):
        load_bvh_folder(tmp_path, scale=0.001)


def test_folder_with_files_in_metres_and_centimetres_trains_on_people(tmp_path):
    humanoid_bvh("bandai", tmp_path / "01_walk.bvh", unit=0.01, frames=200)
    humanoid_bvh("bandai", tmp_path / "02_walk.bvh", unit=1.0, frames=200, seed=3)
    ds = load_bvh_folder(tmp_path)
    assert sorted(ds.info["file_scales"]) == [0.01, 1.0]
    sizes = _sizes(ds)
    assert np.all((sizes > PLAUSIBLE_SIZE[0]) & (sizes < 2.0)), sizes
    for s in ds.test:  # the same skeleton in metres, whatever the file's unit
        knee, hip = ds.skeleton.names.index("LowerLeg_L"), ds.skeleton.names.index("UpperLeg_L")
        np.testing.assert_allclose(np.linalg.norm(s.positions[:, knee] - s.positions[:, hip], axis=-1), 0.42, atol=1e-5)


def _tiny_config(folder: Path) -> Path:
    """Writes a DLow config that trains in a few steps at 30 fps and returns its path."""
    cfg = folder.parent / f"{folder.name}_tiny.py"
    cfg.write_text(
        "from jaxmotion.config import Config\nfrom jaxmotion.models.dlow import CVAEConfig, DLowConfig, QConfig\n"
        "def get_config():\n    return Config(name='tiny_folder', action_metrics=False, data_options={'fps': 30.0}, eval_k=(2,),\n"
        "        method_config=DLowConfig(cvae=CVAEConfig(num_steps=2, batch_size=4, nz=4, nh_rnn=8, nh_mlp=(8,)),\n"
        "                                 q=QConfig(num_steps=1, batch_size=2, nh_rnn=8, nh_mlp=(8,))))\n"
    )
    return cfg


def test_sixty_fps_folder_trains_at_thirty(tmp_path, capsys):
    for i in range(2):
        humanoid_bvh("lafan1", tmp_path / f"0{i + 1}_walk.bvh", fps=60.0, frames=360, seed=i)
    cfg = _tiny_config(tmp_path)
    assert main(["train", "--config", str(cfg), "--data", str(tmp_path), "--workdir", str(tmp_path / "w")]) == 0
    assert "15->60 frames at 30 fps" in capsys.readouterr().out
    lay = json.loads((tmp_path / "w" / "predictor.json").read_text())["layout"]
    assert (lay["fps"], lay["t_his"], lay["t_pred"]) == (30.0, 15, 60)
    ds = load_bvh_folder(tmp_path, fps=30.0)
    assert [len(s.positions) for s in ds.test] == [180, 180]  # 6 s at 30 fps
    # The 30 fps positions are the 60 fps clip's every other frame.
    full = forward_kinematics(read_bvh(tmp_path / "01_walk.bvh")) * 0.01
    np.testing.assert_allclose(ds.test[0].positions, full[::2], atol=1e-5)


def test_scale_flag_reaches_the_folder_loader(tmp_path, capsys):
    assert parse_scale(["0.01"]) == 0.01 and parse_scale(["b_*=0.056444", "*=0.01"]) == {"b_*": 0.056444, "*": 0.01}
    with pytest.raises(ValueError, match="positive"):
        parse_scale(["-1"])
    humanoid_bvh("bandai", tmp_path / "01_a.bvh", unit=0.056444, frames=120)
    humanoid_bvh("bandai", tmp_path / "02_a.bvh", unit=0.056444, frames=120, seed=1)
    with pytest.raises(DataError, match="2 of 2 files have no unit"):
        main(["train", "--data", str(tmp_path), "--workdir", str(tmp_path / "w")])
    with pytest.raises(SystemExit, match="not a number"):
        main(["train", "--data", str(tmp_path), "--scale", "x=y", "--workdir", str(tmp_path / "w")])


# ----------------------------------------------------------------------------------------------
# Joint maps and hierarchies


def test_built_in_conventions_are_recognised(tmp_path):
    for conv, prefix in (("bandai", ""), ("mixamo", "mixamorig:"), ("lafan1", ""), ("smpl22", "")):
        b = read_bvh(humanoid_bvh(conv, tmp_path / f"{conv}.bvh", prefix=prefix, frames=3))
        assert conventions_of(b.names) == [conv]
    if CMU.is_dir():
        assert conventions_of(read_bvh(CMU / "01_01.bvh").names) == ["cmu"]


def test_same_names_other_hierarchy_is_refused_naming_the_difference(tmp_path):
    b = read_bvh(humanoid_bvh("bandai", tmp_path / "odd.bvh", reparent={"Shoulder_L": "Neck"}, frames=3))
    parents = [BANDAI_NAMES.index(p) if p else -1 for p in
               [None, "Hips", "Spine", "Chest", "Neck", "Chest", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Chest",
                "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Hips",
                "UpperLeg_R", "LowerLeg_R", "Foot_R"]]  # fmt: skip
    with pytest.raises(DataError, match=r"hierarchy differs from the model's: model joint 'Shoulder_L' hangs from 'Chest' "
                                        r"\(file joint 'Chest'\), but its file joint 'Shoulder_L' hangs from 'Neck'"):
        match_skeleton(BANDAI_NAMES, parents, b.names, b.parents)
    good = read_bvh(humanoid_bvh("bandai", tmp_path / "good.bvh", frames=3))
    mapping, how = match_skeleton(BANDAI_NAMES, parents, good.names, good.parents)
    assert mapping == {n: n for n in BANDAI_NAMES} and how == "joints: matched by name"


def test_joint_map_file_maps_other_names(tmp_path):
    rename = {n: f"j{i:02d}" for i, n in enumerate(BANDAI_NAMES)}
    clip = humanoid_bvh("bandai", tmp_path / "odd_names.bvh", rename=rename, frames=40)
    b = read_bvh(clip)
    model = jaxmotion.load("bandai")
    with pytest.raises(DataError, match=r"fit no built-in map.*Pass --joint-map FILE"):
        predict_file(model, clip, tmp_path / "o")
    (tmp_path / "map.json").write_text(json.dumps(rename))
    mapping, how = match_skeleton(model.layout["joints"], model.layout["parents"], b.names, b.parents, rename)
    assert mapping == rename and how == "joints: by the given joint map"
    assert main(["predict", "--model", "bandai", str(clip), "--joint-map", str(tmp_path / "map.json"), "--k", "2",
                 "--out", str(tmp_path / "o")]) == 0
    assert read_bvh(tmp_path / "o" / "future_01.bvh").names == b.names


# ----------------------------------------------------------------------------------------------
# The shipped model on other skeletons: BVH forward kinematics == futures.npz, the input's bone lengths


def _check_prediction(clip: Path, out: Path, unit: float, capsys) -> list[str]:
    assert main(["predict", "--model", "bandai", str(clip), "--k", "3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    z = np.load(out / "futures.npz")
    src = read_bvh(clip)
    lengths = lambda p: np.linalg.norm(p[:, 1:] - p[:, list(src.parents[1:])], axis=-1)  # noqa: E731
    want = np.linalg.norm(src.offsets[1:], axis=-1) * unit
    model = jaxmotion.load("bandai")
    mapping, _ = match_skeleton(model.layout["joints"], model.layout["parents"], src.names, src.parents)
    idx = [src.names.index(mapping[n]) for n in model.layout["joints"]]
    for i in range(3):
        b = read_bvh(out / f"future_{i:02d}.bvh")
        assert b.names == src.names and b.parents == src.parents
        p = forward_kinematics(b) * unit
        assert np.abs(p[15:, idx] - z["joints"][i]).max() < 1e-3
        np.testing.assert_allclose(lengths(p), np.broadcast_to(want, (75, len(want))), rtol=1e-5, atol=1e-7)
    return printed.splitlines()


@pytest.mark.parametrize("conv,prefix", [("mixamo", "mixamorig:"), ("lafan1", "")])
def test_shipped_model_predicts_on_mixamo_and_lafan1_skeletons(conv, prefix, tmp_path, capsys):
    clip = humanoid_bvh(conv, tmp_path / f"{conv}.bvh", prefix=prefix, unit=0.01, frames=120)
    lines = _check_prediction(clip, tmp_path / "o", 0.01, capsys)
    assert any(f"the file's {conv} names (built-in joint map)" in s for s in lines)


@pytest.mark.skipif(not CMU.is_dir(), reason=f"shared CMU BVH clips not found at {CMU}")
@pytest.mark.parametrize("clip", ["01_01.bvh", "01_03.bvh"])
def test_shipped_model_predicts_on_the_cmu_clips(clip, tmp_path, capsys):
    lines = _check_prediction(CMU / clip, tmp_path / "o", 0.056444, capsys)
    assert any("units: 0.056444 m per file unit (guessed from the skeleton), a body 1.3" in s for s in lines)
    assert any("resampled from 120 to 30 fps" in s for s in lines)
    assert any("the file's cmu names" in s for s in lines)


# ----------------------------------------------------------------------------------------------
# jaxmotion eval --model on a folder whose every clip is a test clip


def test_eval_of_the_shipped_model_on_a_fabricated_folder(tmp_path, capsys):
    humanoid_bvh("lafan1", tmp_path / "clips" / "walk_a.bvh", fps=60.0, frames=400)
    humanoid_bvh("lafan1", tmp_path / "clips" / "walk_b.bvh", fps=60.0, frames=300, seed=1, unit=1.0)
    humanoid_bvh("lafan1", tmp_path / "clips" / "short.bvh", fps=60.0, frames=100, seed=2)  # 50 frames at 30 fps: no window
    assert main(["eval", "--model", "bandai", "--data", str(tmp_path / "clips"), "--workdir", str(tmp_path / "w"), "--k", "10"]) == 0
    printed = capsys.readouterr().out
    assert "3 clips, all test" in printed and "files at 60 fps" in printed
    assert "skipped: 1 clip(s) not longer than t_his + t_pred = 75 frames: short.bvh" in printed
    records = json.loads((tmp_path / "w" / "metrics.json").read_text())
    # 400 and 300 frames at 60 fps -> 200 and 150 at 30; test windows of 75 frames every 15 (T > 75 + start): 9 + 5.
    model = jaxmotion.load("bandai")
    assert {r["method"] for r in records} == set(model.predictors(10)) and all(r["n_windows"] == 14 and r["K"] == 10 for r in records)
    m = {r["method"]: r["metrics"] for r in records}
    assert all(np.isfinite(v["ADE"]) and v["ADE"] > 0 for v in m.values()) and m[model.main_method(10)]["APD"] > 0
    assert all(np.isfinite(v["FFE"]) and v["FFE"] > 0 for v in m.values()) and all("retargeted onto the model" in r["dataset"] for r in records)
    assert not (tmp_path / "w" / "predictor.json").exists()


@pytest.mark.skipif(not CMU.is_dir(), reason=f"shared CMU BVH clips not found at {CMU}")
def test_eval_of_the_shipped_model_on_the_cmu_folder(tmp_path, capsys):
    assert main(["eval", "--model", "bandai", "--data", str(CMU), "--workdir", str(tmp_path / "w"), "--k", "5"]) == 0
    records = json.loads((tmp_path / "w" / "metrics.json").read_text())
    # 2752 and 4511 frames at 120 fps -> 688 and 1128 at 30 fps: (688 - 75) // 15 + 1 + (1128 - 75) // 15 + 1 windows.
    assert all(r["n_windows"] == 41 + 71 for r in records)
    assert "cmu names" in capsys.readouterr().out


# ----------------------------------------------------------------------------------------------
# The viewer finds a run's data; frame rates print rounded


def test_view_finds_the_data_relative_to_the_run_or_says_pass_data(tmp_path, monkeypatch):
    from jaxmotion.tools.viewer import run_data

    (tmp_path / "project" / "data" / "clips").mkdir(parents=True)
    run = tmp_path / "project" / "runs" / "r"
    run.mkdir(parents=True)
    monkeypatch.chdir(tmp_path)  # elsewhere: the recorded relative path does not exist from here
    assert run_data("data/clips", run) == str(tmp_path / "project" / "data" / "clips")
    assert run_data("synthetic", run) == "synthetic"
    with pytest.raises(DataError, match="pass --data PATH"):
        run_data("data/missing", run)


def test_frame_rates_print_rounded(tmp_path):
    clip = humanoid_bvh("bandai", tmp_path / "c.bvh", fps=1 / 0.033334, frames=100)
    assert "Frame Time: 0.0333340000" in clip.read_text()
    lines = predict_file(jaxmotion.load("bandai"), clip, tmp_path / "o", k=2, gif=False)
    assert "(100 frames at 30 fps, 21 joints)" in lines[0] and not any("resampled" in s for s in lines)


def test_predict_refuses_a_clip_whose_units_make_no_person(tmp_path, capsys):
    clip = humanoid_bvh("bandai", tmp_path / "tiny_units.bvh", unit=0.056444, frames=100)
    assert main(["predict", "--model", "bandai", str(clip), "--out", str(tmp_path / "o")]) == 2
    assert "would fit: " in capsys.readouterr().err and not (tmp_path / "o").exists()
    assert main(["predict", "--model", "bandai", str(clip), "--scale", "0.056444", "--k", "2", "--out", str(tmp_path / "o")]) == 0


# ----------------------------------------------------------------------------------------------
# What predict, eval and view say


def test_predict_unit_error_names_the_clip_and_its_one_option(tmp_path, capsys):
    clip = humanoid_bvh("bandai", tmp_path / "tiny_units.bvh", unit=0.056444, frames=100)
    assert main(["predict", "--model", "bandai", str(clip), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{clip}: units" in err and "--scale NUMBER" in err
    assert "PATTERN" not in err and "1 of 1 files" not in err  # predict takes one clip and one number


def test_a_body_of_an_adult_read_in_inches_is_refused_and_no_such_unit_offered(tmp_path, capsys):
    from jaxmotion.data.units import body_size

    clip = humanoid_bvh("bandai", tmp_path / "c.bvh", unit=0.01, frames=100)
    size = body_size(read_bvh(clip))  # file units
    small = 0.57 / size  # metres per unit that make the body 0.57 m across
    assert main(["predict", "--model", "bandai", str(clip), "--scale", f"{small:.6g}", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "= 0.57 m (not a person)" in err and not (tmp_path / "o").exists()
    offered = [float(m) for m in re.findall(r"\(\d[\d.e-]*: (\d+\.\d+) m\)", err)]
    assert offered and min(offered) >= PLAUSIBLE_SIZE[0] > 0.57


def test_folder_with_another_hierarchy_names_the_joint(tmp_path):
    humanoid_bvh("bandai", tmp_path / "clips" / "a.bvh", frames=80)
    humanoid_bvh("bandai", tmp_path / "clips" / "b.bvh", frames=80, reparent={"Shoulder_L": "Neck"})
    with pytest.raises(DataError, match=r"b\.bvh: skeleton differs from .*a\.bvh's: joint 'Shoulder_L' hangs from 'Neck' here, "
                                        r"from 'Chest' there"):
        load_bvh_folder(tmp_path / "clips")


def test_predict_counts_input_frames_prints_one_wrote_line_and_view_says_what_the_folder_is(tmp_path, capsys):
    clip = humanoid_bvh("bandai", tmp_path / "c.bvh", fps=60.0, frames=300)
    assert main(["predict", "--model", "bandai", str(clip), "--frame", "100", "--k", "3", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.splitlines()
    z = np.load(tmp_path / "o" / "futures.npz")
    assert int(z["end_frame"]) == 100 and int(z["end_frame_model"]) == 50  # --frame counts input frames, and so does the npz
    assert "observed: input frames 72..100" in out  # model frames 36..50 at 30 fps
    assert not any("has no predictor" in s for s in out)
    assert [s for s in out if s.startswith("wrote")] == [f"wrote {tmp_path / 'o'}/: futures.npz, future_00.bvh .. future_02.bvh "
                                                          "(3 BVH files), samples.gif"]
    assert any(s.startswith("note: first predicted frame: joints ") for s in out)
    pytest.importorskip("plotly")
    assert main(["view", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "the output of `jaxmotion predict`" in err and "jaxmotion eval" not in err


def test_far_from_training_names_proportions_speed_and_pose_range():
    from jaxmotion.train.manifest import far_from_training

    manifest = {"layout": {"joints": ["Root", "Spine", "Head"], "parents": [-1, 0, 1]}, "bone_lengths": [0.0, 0.5, 0.4],
                "motion_ranges": {"speed_p99": 1.0, "reach_p99": 1.0}}
    still = np.tile(np.array([[0, 0, 0], [0, 0.5, 0], [0, 0.9, 0]], float), (15, 1, 1))
    assert far_from_training(manifest, still, 30.0) == []
    assert far_from_training(manifest, still * 1.3, 30.0) == []  # a taller body is not far
    tall = still * [1.0, 2.0, 1.0]  # bones 1.0 and 0.8 m: twice the training data's; the head 1.8 m from the root
    got = far_from_training(manifest, tall, 30.0)
    assert got[0] == "proportions: Spine 1.00 m (training data 0.50 m), Head 0.80 m (training data 0.40 m)"
    assert got[1].startswith("pose range: a joint 1.80 m from the root") and len(got) == 2
    fast = still + np.array([[0.0, 0, 0], [0.1, 0, 0]])[np.arange(15) % 2][:, None]  # 0.1 m per frame along x at 30 fps: 3 m/s
    assert far_from_training(manifest, fast, 30.0) == ["speed: joints move 3.00 m/s on average (training data: 99% of frames under 1.00 m/s)"]


def test_the_shipped_example_clip_reads_and_predicts(tmp_path, capsys):
    from jaxmotion.examples import cmu_clip
    from jaxmotion.tools.predict_file import read_motion

    clip = cmu_clip()
    m = read_motion(clip)
    assert m.positions.shape == (300, 31, 3) and abs(m.fps - 30) < 0.01 and abs(m.scale - 0.056444) < 1e-9
    assert 1.0 < np.ptp(m.positions[0], axis=0).max() < 2.0  # a person, in metres
    assert main(["predict", "--model", "bandai", str(clip), "--k", "2", "--out", str(tmp_path / "o")]) == 0
    assert np.load(tmp_path / "o" / "futures.npz")["futures"].shape[:2] == (2, 60)
    with pytest.raises(FileNotFoundError, match="not a shipped example clip"):
        cmu_clip("nope")
