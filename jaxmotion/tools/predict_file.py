"""Predict from your own motion file: read it, bring it to a trained model's layout, draw K futures, write them.

    jaxmotion predict runs/dlow_synthetic --input clip.bvh --k 5 --out futures/

`read_motion` reads a BVH clip (forward kinematics, units guessed as `formats.bvh.guess_scale` does
unless `scale` is given, and checked against a person's size, `data.units`) or an npz of joint positions (`positions` (T, J, 3), optional `names`,
`fps`, `scale` (metres per unit, default 1), `up_axis`), or a C3D marker file (labels without
the `Subject:` prefix, metres, NaN at gaps: a marker model's input, `predict_markers`). `predict_file`
converts to metres, turns the up axis onto the model's, resamples a different frame rate by linear interpolation of
joint positions and makes frames root-relative with the root dropped. Joints are matched by
`joint_maps.match_skeleton`: a `--joint-map`, the same names, or a built-in convention (CMU,
Mixamo, LAFAN1, SMPL, Bandai-Namco), the file's hierarchy checked against the model's.

`predict_file` puts every future on the input's own skeleton (`retarget.fit_bvh`: the observed
frames, then the future, the root held at its last observed place since the models predict
root-relative motion; each joint's rotation points its bones along the predicted ones) and writes
one BVH per future, `futures.npz` and `samples.gif`, all three showing that motion: `futures` and
`joints` in the npz are the forward kinematics of the BVH files (the input's bone lengths), and
`futures_raw` / `joints_raw` the model's output as it came.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import numpy as np

from jaxmotion.data.plausible import check_positions
from jaxmotion.data.units import body_size, file_scales
from jaxmotion.errors import DataError, UsageError
from jaxmotion.formats.atomic import savez_atomic
from jaxmotion.formats.bvh import MAX_JOINTS, Bvh, forward_kinematics, read_bvh
from jaxmotion.formats.bvh_write import read_end_sites, write_bvh
from jaxmotion.data.windows import resample  # noqa: F401 (also part of this module's interface)
from jaxmotion.formats.c3d import read_c3d
from jaxmotion.formats.npz import read_arrays
from jaxmotion.tools.joint_maps import match_skeleton
from jaxmotion.tools.predict_markers import predict_markers
from jaxmotion.tools.predictor import MotionPredictor
from jaxmotion.tools.retarget import bvh_from_positions, fit_bvh
from jaxmotion.train.manifest import far_from_training


@dataclasses.dataclass
class Motion:
    """Global joint positions of a file, in metres, with what is needed to write results back onto it."""

    path: Path
    names: tuple[str, ...] | None  # None: an npz without names (joints in the model's order)
    positions: np.ndarray  # (T, J, 3) metres
    fps: float | None
    scale: float  # metres per file unit
    up_axis: int | None
    bvh: Bvh | None = None  # the source skeleton when the file is a BVH
    notes: list[str] = dataclasses.field(default_factory=list)


def read_motion(path: str | Path, scale: float | None = None) -> Motion:
    """Returns the joint positions of a BVH clip or an npz file (module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if path.suffix.lower() == ".bvh":
        bvh = read_bvh(path)
        if scale is not None:
            _scale(path, scale)  # a negative scale would mirror the body
        s = file_scales({path: bvh}, scale, path.parent, one_file=True)[path]  # guessed or given, checked against a person's size
        notes = [f"units: {s:g} m per file unit ({'guessed from the skeleton' if scale is None else '--scale'}), "
                 f"a body {body_size(bvh) * s:.2f} m across"]
        return _checked(Motion(path, bvh.names, forward_kinematics(bvh) * s, bvh.fps, s, 1, bvh, notes))
    if path.suffix.lower() == ".c3d":  # markers, NaN at gaps, for marker models (`predict_markers`)
        rec = read_c3d(path)
        s = {"mm": 1e-3, "cm": 1e-2, "dm": 0.1, "m": 1.0}[rec.units]
        pos = check_positions(path, rec.points, "marker positions", gaps=True, units=f"POINT:UNITS says {rec.units}")
        return _checked(Motion(path, rec.labels, pos.astype(np.float64), rec.rate, s, None, None, [f"units: {rec.units} (POINT:UNITS)"]), unique_names=False)
    if path.suffix.lower() == ".npz":
        z = read_arrays(path, ("positions", "names", "fps", "scale", "up_axis"), what="clip of joint positions", required=("positions",))
        names = tuple(str(n) for n in z["names"].reshape(-1)) if "names" in z else None
        if names is not None and len(names) != (z["positions"].shape[1] if z["positions"].ndim == 3 else -1):
            raise DataError(path, f"{len(names)} names for 'positions' of shape {z['positions'].shape}")
        try:
            s = _number(z, "scale") if "scale" in z else (1.0 if scale is None else scale)
            fps = _number(z, "fps") if "fps" in z else None
            up = _number(z, "up_axis") if "up_axis" in z else None
        except (TypeError, ValueError) as e:
            raise DataError(path, f"'scale', 'fps' and 'up_axis' must be single real numbers ({e})") from None
        if up is not None and up not in (0, 1, 2):
            raise DataError(path, f"'up_axis' must be 0, 1 or 2 (x, y or z), got {up:g}")
        pos = z["positions"]
        if isinstance(pos, np.ndarray) and np.issubdtype(pos.dtype, np.floating):
            pos = pos.astype(np.float64) * _scale(path, s)
        pos = check_positions(path, pos, "'positions'", units=f"{s:g} m per unit")
        return _checked(Motion(path, names, pos.astype(np.float64), fps, s, None if up is None else int(up), None, [f"units: {s:g} m per unit"]))
    raise DataError(path, "expected a .bvh clip, an .npz of joint positions or a .c3d marker file")


def _number(z: dict, key: str) -> float:
    """Returns the single real number stored under `key` (a bool, complex or text value is refused)."""
    a = z[key]
    if a.size != 1 or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{key!r} is {a.dtype} of shape {a.shape}")
    return float(a.reshape(-1)[0])


def _scale(path: Path, s: float) -> float:
    """Returns the scale `s` (metres per unit) once checked: a negative one would mirror the body."""
    if not (np.isfinite(s) and s > 0):
        raise DataError(path, f"scale must be a finite number of metres per unit > 0, got {s}")
    return s


def _checked(m: Motion, unique_names: bool = True) -> Motion:
    """Returns `m` after checking what a file could make wrong without a parser noticing."""
    if m.fps is not None and not (np.isfinite(m.fps) and m.fps > 0):
        raise DataError(m.path, f"frame rate must be a finite number > 0, got {m.fps}")
    if unique_names and m.names is not None:  # C3D labels are matched by `predict_markers.match_markers`
        seen = set()
        twice = [n for n in m.names if n in seen or seen.add(n)]
        if twice:  # joints are matched by name: which one is meant?
            raise DataError(m.path, f"joint names used twice: {sorted(set(twice))}")
    if m.positions.shape[1] > MAX_JOINTS:
        raise DataError(m.path, f"{m.positions.shape[1]} joints, more than {MAX_JOINTS} (formats.bvh.MAX_JOINTS); not a body")
    return m


def match_joints(motion: Motion, joints: list[str], parents: list[int] | None = None, joint_map: dict[str, str] | None = None) -> np.ndarray:
    """Returns the input joint index of each model joint, `(len(joints),)` (`joint_maps.match_skeleton`: a joint map, the names, or a built-in
    convention; the BVH's hierarchy checked against `parents`), or raises `DataError` saying what differs."""
    if motion.names is None:
        if motion.positions.shape[1] != len(joints):
            raise DataError(
                motion.path, f"{motion.positions.shape[1]} unnamed joints, the model has {len(joints)} ({joints}); "
                "add 'names' to the npz"
            )
        motion.notes.append("joints: unnamed, taken in the model's order")
        return np.arange(len(joints))
    file_parents = motion.bvh.parents if motion.bvh is not None and parents is not None else None
    mapping, how = match_skeleton(joints, parents, motion.names, file_parents, joint_map, where=motion.path)
    if how != "joints: matched by name":
        motion.notes.append(how)
    extra = [n for n in motion.names if n not in mapping.values()]
    if extra:
        motion.notes.append(f"joints: {len(extra)} not in the model ignored ({extra})")
    return np.array([motion.names.index(mapping[n]) for n in joints])


def _roll(p: np.ndarray, shift: int) -> np.ndarray:
    return np.roll(p, shift, axis=-1)  # a cyclic permutation of x, y, z: a proper rotation


def predict_file(
    model: MotionPredictor, path: str | Path, out: str | Path, *, frame: int | None = None, k: int | None = None,
    method: str | None = None, seed: int = 0, scale: float | None = None, gif: bool = True,
    joint_map: dict[str, str] | None = None, retarget: bool = True,
) -> list[str]:
    """Writes the K futures of the window of `path` ending at input frame `frame` to `out`; returns the lines to print.

    Args:
        model: a trained model (`jaxmotion.load`), of joints or of markers.
        path: a BVH, C3D or NPZ clip (NPZ: `positions` `(T, J, 3)`, optional `names`, `fps`); its joints
            are matched to the model's by name, by a built-in convention or by `joint_map`, and it is
            resampled to the model's frame rate and turned onto its up axis when they differ.
        out: a folder; receives `futures.npz` (the K futures as frame vectors and as joint positions in
            metres, the observed window, the ground truth where the clip has it), `future_NN.bvh` per
            future (BVH input) and `samples.gif` (with `gif`).
        frame: the input frame the observed window ends at (default: the last frame whose whole future
            is in the clip, so that the GIF shows the ground truth; else the clip's last frame).
        k: the number of futures (default: the model's).
        method: the predictor (default: the model's own).
        seed: the `jax.random` seed of the futures.
        scale: metres per file unit (default: guessed from the file).
        gif: also write the animation.
        joint_map: `{model joint: input joint}` for names that differ.
        retarget: the model sees the window on its own skeleton and facing, and answers on the input's
            bones (`predictor.retargeted`).

    Returns:
        The lines `jaxmotion predict` prints: what was read, every adjustment made, what was written.

    Raises:
        jaxmotion.errors.DataError: the clip cannot be read, its joints do not match the model's, or it is
            shorter than `t_his` frames at the model's rate.
        jaxmotion.errors.UsageError: `out` is a file, or `frame` is outside the clip.
    """
    if not str(out).strip():  # Path("") is the current folder
        raise UsageError("--out is empty; give the folder to write futures.npz, future_NN.bvh and samples.gif into")
    if Path(out).exists() and not Path(out).is_dir():
        raise UsageError(f"--out {out} is a file; give a folder (it receives futures.npz, future_NN.bvh, samples.gif)")
    lay = model.layout
    if lay["frames"] == "global":  # a marker model (MOJO on markers): labels, gaps, canonical frame
        return predict_markers(model, read_motion(path, scale), out, frame=frame, k=k, method=method, seed=seed, gif=gif)
    if lay["frames"] != "root_relative":
        raise DataError(path, f"the model predicts {lay['frames']} frames; predict from a file supports joint and marker models")
    motion = read_motion(path, scale)
    idx = match_joints(motion, lay["joints"], lay["parents"], joint_map)
    pos = motion.positions
    notes = motion.notes
    shift = 0
    if motion.bvh is None and motion.up_axis is not None and lay.get("up_axis") is None:
        # An npz's declared axis is honoured or refused, never dropped (a BVH's Y up is a convention, not a declaration).
        raise DataError(path, f"'up_axis' is {'xyz'[motion.up_axis]}, but the model records no up axis to turn it onto; "
                              "remove 'up_axis' from the npz to give the positions in the model's own axes")
    if lay.get("up_axis") is not None and motion.up_axis is not None and motion.up_axis != lay["up_axis"]:
        shift = (lay["up_axis"] - motion.up_axis) % 3
        pos = _roll(pos, shift)
        notes.append(f"up axis: input {'xyz'[motion.up_axis]} turned onto the model's {'xyz'[lay['up_axis']]}")
    fps_in, fps = motion.fps, lay["fps"]
    n_in = pos.shape[0]
    if frame is not None and not 0 <= frame < n_in:
        raise UsageError(f"--frame must be in [0, {n_in}) for {motion.path} ({n_in} frames), got {frame}")
    if fps_in is None:
        notes.append(f"frame rate: not in the file, taken as the model's {fps:g} fps")
        fps_in = fps
    ratio = fps / fps_in
    if abs(ratio - 1) > 0.01:
        pos = resample(pos, fps_in, fps, str(motion.path))
        notes.append(
            f"frame rate: resampled from {round(fps_in, 2):g} to {round(fps, 2):g} fps by linear interpolation of joint positions "
            f"({n_in} -> {pos.shape[0]} frames); --frame counts input frames"
        )
    else:
        ratio = 1.0
    n = pos.shape[0]
    t_his, t_pred = lay["t_his"], lay["t_pred"]
    if frame is None:
        end = n - t_pred - 1 if n >= t_his + t_pred else n - 1
    else:
        end = min(n - 1, int(round(frame * ratio)))
    if end + 1 < t_his:
        raise DataError(
            motion.path, f"the observed window ending at frame {end} (model rate) has fewer than t_his = {t_his} frames "
            f"({t_his / fps:.2f} s at {fps:g} fps); the clip has {n} frames at that rate"
        )
    joints = pos[:, idx]  # (n, J, 3) metres, model joint order
    frames = (joints[:, 1:] - joints[:, :1]).reshape(n, -1).astype(np.float32)
    x = frames[end + 1 - t_his : end + 1]
    far = far_from_training(model.manifest, joints[end + 1 - t_his : end + 1], fps)
    gt = frames[end + 1 : end + 1 + t_pred] if end + t_pred < n else None
    k = model.default_k if k is None else k
    method = method or model.main_method(k)
    retarget = retarget and model.bone_lengths is not None
    futures = model.predict(x, k, jax.random.key(seed), method, retarget=retarget)  # (K, t_pred, D)
    if retarget:
        notes.append("skeleton: the observed frames put on the model's skeleton (its training data's bone lengths"
                     f"{' and facing' if model.facing is not None else ''}, the input's bone directions) before prediction, "
                     "the futures put back on the input's bones (--no-retarget: the input as it is)")

    # World joint positions of observed + future frames, the root held at its last observed place.
    root = joints[end, 0]
    raw_j = np.concatenate([np.zeros((k, t_pred, 1, 3)), futures.reshape(k, t_pred, -1, 3)], axis=2) + root
    obs_j = joints[end + 1 - t_his : end + 1]
    to_file = lambda p: _roll(p, -shift) / motion.scale  # noqa: E731  (the input's world and units)
    from_file = lambda p: _roll(p * motion.scale, shift)  # noqa: E731
    if motion.bvh is not None:
        template = dataclasses.replace(motion.bvh, frame_time=1.0 / fps)
        known = np.zeros(template.num_joints, bool)
        known[idx] = True
        # Reference pose (twist, joints the model does not predict): the input's frame at the window's end.
        ref_motion = template.motion[min(int(round(end / ratio)), template.num_frames - 1)]
        tpl = dataclasses.replace(template, motion=ref_motion[None])
    fitted, kept = [], []
    for i in range(k):
        seq = to_file(np.concatenate([obs_j, raw_j[i]]))  # (t_his + t_pred, J_model, 3)
        if motion.bvh is not None:
            targets = np.zeros((seq.shape[0], template.num_joints, 3))
            targets[:, idx] = seq
            try:
                b = fit_bvh(tpl, targets, known, reference_frame=0)
            except ValueError as e:  # a joint that cannot rotate (CHANNELS 0) but must to follow the future
                raise DataError(motion.path, f"the futures cannot be written on this skeleton ({e}); nothing was written") from None
            kept.append(from_file(forward_kinematics(b)[:, idx]))
        else:  # the skeleton of the last observed frame
            b = bvh_from_positions(tuple(lay["joints"]), tuple(lay["parents"]), seq, fps, rest_frame=t_his - 1)
            kept.append(from_file(forward_kinematics(b)))
        fitted.append(b)
    # What the BVH files show: the predicted bone directions on the input's bone lengths (`retarget.fit_bvh`).
    kept_j = np.stack(kept)[:, t_his:]  # (K, t_pred, J, 3)
    kept_f = (kept_j[:, :, 1:] - kept_j[:, :, :1]).reshape(k, t_pred, -1).astype(np.float32)
    moved = np.linalg.norm(kept_j - raw_j, axis=-1)
    notes.append(
        f"skeleton: futures fitted to the input's skeleton (the BVH files, 'futures' and 'joints' in futures.npz); "
        f"joints moved {100 * moved.mean():.1f} cm on average, {100 * moved.max():.1f} cm at most, from the model's "
        "output ('futures_raw')"
    )
    observed_j = np.stack(kept)[0, :t_his]
    jump = np.linalg.norm(kept_j[:, 0] - observed_j[-1], axis=-1).mean()
    step = np.linalg.norm(observed_j[-1] - observed_j[-2], axis=-1).mean() if t_his > 1 else 0.0
    notes.append(f"first predicted frame: joints {100 * jump:.1f} cm from the last observed frame on average "
                 f"(the observed motion moves them {100 * step:.1f} cm per frame)")
    to_input = lambda f: min(n_in - 1, int(round(f / ratio)))  # noqa: E731  (a model-rate frame, counted as --frame counts)
    first_in, end_in = to_input(end + 1 - t_his), to_input(end)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    savez_atomic(
        out / "futures.npz", futures=kept_f, futures_raw=futures, observed=x,
        ground_truth=gt if gt is not None else np.zeros((0,) + x.shape[1:]),
        joints=kept_j.astype(np.float32), joints_raw=raw_j.astype(np.float32), observed_joints=observed_j.astype(np.float32),
        names=np.array(lay["joints"]), parents=np.array(lay["parents"]), fps=fps, t_his=t_his, t_pred=t_pred, method=method,
        k=k, end_frame=end_in, end_frame_model=end, input=str(motion.path), notes="\n".join(notes),
    )
    written = [out / "futures.npz"]
    end_sites = read_end_sites(motion.path) if motion.bvh is not None else None
    for i, b in enumerate(fitted):
        written.append(write_bvh(out / f"future_{i:02d}.bvh", b, end_sites))
    if gif:
        from jaxmotion.pictures.animate import animate_futures

        written.append(animate_futures(
            x, kept_f, gt, tuple(lay["parents"]), out / "samples.gif", fps=fps,
            title=f"{motion.path.name}: frames {first_in}-{end_in} observed, {method}, K={k}",
        ))
    lines = [
        f"input: {motion.path} ({n_in} frames at {round(motion.fps or fps, 2):g} fps, {len(motion.names or idx)} joints)",
        f"model: {model.run_dir} ({model.manifest['dataset']['name']}, {model.config.method}; {len(lay['joints'])} joints, "
        f"{t_his} -> {t_pred} frames at {fps:g} fps)",
        *[f"note: {s}" for s in notes],
        *[f"warning: far from the model's training data: {s}"
          + ("; the model sees the clip on its own skeleton (retargeted)" if retarget and s.startswith("proportions") else "")
          for s in far],
        f"observed: input frames {first_in}..{end_in}" + ("" if gt is not None else " (no ground truth after it)"),
        f"predicted: K={k} futures with {method!r}; BVH files hold the {t_his} observed frames, then {t_pred} predicted, "
        "the root held at its last observed position",
        wrote_line(out, written),
    ]
    return lines


def wrote_line(out: Path, written: list[Path]) -> str:
    """Returns one line naming the files written to `out` (a run of numbered BVH files as its first and last)."""
    bvhs = [p.name for p in written if p.suffix == ".bvh"]
    others = [p.name for p in written if p.suffix != ".bvh"]
    runs = [bvhs[0] if len(bvhs) == 1 else f"{bvhs[0]} .. {bvhs[-1]} ({len(bvhs)} BVH files)"] if bvhs else []
    return f"wrote {out}/: {', '.join(others[:1] + runs + others[1:])}"
