"""A trained run directory as a self-contained predictor: `jaxmotion.load(run_dir).predict(x, k, key)`.

    model = jaxmotion.load("runs/dlow_synthetic")
    model.methods                                   # ['cvae', 'dlow', 'zero_velocity'] at the default K
    futures = model.predict(x, k=50, key=jax.random.key(0))   # x (t_his, D) -> (50, t_pred, D)
    export("runs/dlow_synthetic", "dlow.msgpack")   # one inference-only file; load("dlow.msgpack"), load("bandai") (shipped)

Training writes `predictor.json` beside the stage folders (`write_manifest`): the config, the
skeleton (joint names, parents, median bone lengths), the frame layout (joints kept, root dropped,
root-relative or canonical global frames, metres, fps, t_his / t_pred) and the dataset it came
from. `load` needs nothing else: each stage's parameters are restored from its orbax checkpoint
without a target structure and checked against the shapes its `stage.json` lists, so no training
data (which the methods' `stages` read to build their batches) is touched.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.config import Config
from jaxmotion.data.types import MotionDataset, Skeleton
from jaxmotion.errors import CheckpointError, ConfigError, UsageError
from jaxmotion.train.manifest import MANIFEST, VERSION, bone_lengths, layout, write_manifest  # noqa: F401 (public here too)

def config_from_dict(d: dict) -> Config:
    """Returns the `Config` that `config.to_dict` wrote (the method's settings rebuilt from `method_config_type`)."""
    d = dict(d)
    type_name = d.pop("method_config_type", None)
    mc = d.pop("method_config", None)
    cfg = _build(Config, {**d, "method_config": None})
    if type_name is not None and mc is not None:
        # Only a registered method's settings type: a run folder from elsewhere names no module to import.
        from jaxmotion.methods import methods

        known = {f"{t.__module__}.{t.__name__}": t for t in (m.config_type for m in methods().values())}
        if type_name not in known:
            raise ConfigError("the run's config", [f"method_config_type {type_name!r} is not a registered method's settings type ({sorted(known)})"])
        cfg = dataclasses.replace(cfg, method_config=_build(known[type_name], mc))
    return cfg


def run_config(run_dir: str | Path) -> tuple[Config, str]:
    """Returns `(config, data source)` of a trained run: from its `predictor.json`, else from its metrics.json records.

    The second is for runs evaluated before `predictor.json` existed (their records hold the
    config; the source is then the config's `dataset`). FileNotFoundError when the folder has neither.
    """
    run_dir = Path(run_dir)
    manifest, records = run_dir / MANIFEST, run_dir / "metrics.json"
    if manifest.is_file():
        m = json.loads(manifest.read_text())
        return config_from_dict(m["config"]), m["dataset"]["source"]
    if records.is_file():
        cfg = config_from_dict(json.loads(records.read_text())[0]["config"])
        return cfg, cfg.dataset
    raise FileNotFoundError(f"{run_dir}: neither {MANIFEST} nor metrics.json; not a trained run (jaxmotion train / run write them)")


def _build(cls, d: dict):
    hints = typing.get_type_hints(cls)
    kw = {}
    for f in dataclasses.fields(cls):
        if f.name in d and f.init:
            kw[f.name] = _value(hints.get(f.name, Any), d[f.name])
    return cls(**kw)


def _value(hint, v):
    if v is None:
        return None
    if dataclasses.is_dataclass(hint) and isinstance(v, dict):
        return _build(hint, v)
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Union or (origin is not None and type(None) in args):
        for a in args:
            if a is not type(None) and (dataclasses.is_dataclass(a) or typing.get_origin(a) is tuple or a is tuple):
                return _value(a, v)
        return v
    if (origin is tuple or hint is tuple) and isinstance(v, list):
        inner = args[0] if args else Any
        return tuple(_value(inner, x) for x in v)
    return v


class MotionPredictor:
    """A trained run: `predict(x, k, key)` draws K futures of frames in the model's layout (`layout`)."""

    def __init__(self, run_dir: str | Path, stages: tuple[str, ...] | None = None):
        from jaxmotion.train.runner import MANIFEST as STAGE_MANIFEST
        from jaxmotion.train.runner import restore_untargeted

        self.run_dir = Path(run_dir)
        path = self.run_dir / MANIFEST
        if not path.is_file() and (self.run_dir / "futures.npz").is_file():
            raise FileNotFoundError(
                f"{self.run_dir}: the output of `jaxmotion predict` (futures.npz, future_NN.bvh, samples.gif), not a trained run; "
                "its futures are in futures.npz and samples.gif, and a model is given to view / predict / eval as the "
                "run folder or model file that predict read"
            )
        if not path.is_file():
            raise FileNotFoundError(
                f"{path}: not found; {self.run_dir} is not a trained run (jaxmotion run / train write it), "
                "or it was trained before predictor.json existed: `jaxmotion eval` on it writes it"
            )
        try:
            self._setup(json.loads(path.read_text()))
        except (ValueError, KeyError, TypeError) as e:  # cut short, edited by hand, or another program's file
            raise CheckpointError(f"{path}: unreadable ({type(e).__name__}: {e}); `jaxmotion eval` on the run writes it again") from None
        self.params = {}
        for d in sorted(self.run_dir.iterdir()):
            m = d / STAGE_MANIFEST
            if stages is not None and d.name not in stages:
                continue
            if m.is_file() and json.loads(m.read_text()).get("method") == self.method.name and (d / "ckpt").is_dir():
                self.params[d.name] = restore_untargeted(d)
        if not self.params:
            raise CheckpointError(f"{self.run_dir}: no trained stage of method {self.method.name!r}")
        if stages is not None and set(stages) - set(self.params):
            raise CheckpointError(f"{self.run_dir}: stage(s) {sorted(set(stages) - set(self.params))} not trained")

    @classmethod
    def from_parts(cls, manifest: dict, params: dict, source: str | Path) -> MotionPredictor:
        """Returns the predictor of a `predictor.json` dict and `{stage: parameters}` (an exported model, `read_model`)."""
        self = cls.__new__(cls)
        self.run_dir = Path(source)
        self._setup(manifest)
        self.params = dict(params)
        return self

    def _setup(self, manifest: dict) -> None:
        from jaxmotion.methods import get_method

        self.manifest = manifest
        self.layout = self.manifest["layout"]
        self.config = config_from_dict(self.manifest["config"])
        self.method = get_method(self.config.method)
        lay = self.layout
        self.skeleton = Skeleton(tuple(lay["joints"]), tuple(lay["parents"]))
        # A dataset without sequences: what the methods' predictors read (skeleton, lengths, fps, info).
        info = {"frames": "global"} if lay["frames"] == "global" else {}
        if lay.get("up_axis") is not None:
            info["up_axis"] = lay["up_axis"]
        self.dataset = MotionDataset(
            name=self.manifest["dataset"]["name"], skeleton=self.skeleton, fps=lay["fps"], t_his=lay["t_his"],
            t_pred=lay["t_pred"], mm_threshold=lay["mm_threshold"], train=[], test=[], info=info,
        )
        self._fns: dict[tuple[int, bool], dict] = {}

    @property
    def t_his(self) -> int:
        return self.layout["t_his"]

    @property
    def t_pred(self) -> int:
        return self.layout["t_pred"]

    @property
    def dim(self) -> int:
        return self.layout["dim"]

    @property
    def default_k(self) -> int:
        return max(self.config.eval_k)

    @property
    def bone_lengths(self) -> np.ndarray | None:
        """Returns the `(J - 1,)` bone lengths of the model's skeleton (the training frames' medians, m; bone i ends at
        joint i + 1), or None for a marker model or a run whose manifest has none."""
        b = self.manifest.get("bone_lengths")
        return None if b is None or self.layout["frames"] != "root_relative" else np.asarray(b[1:], np.float32)

    @property
    def facing(self) -> tuple[float, int, int, int] | None:
        """Returns `(degrees, left hip, right hip, up axis)`: the training data's most common facing
        (`manifest.facing_angle`), or None where the manifest has none."""
        f, up = self.manifest.get("facing"), self.layout.get("up_axis")
        if f is None or up is None:
            return None
        names = self.skeleton.names
        return float(f["degrees"]), names.index(f["left"]), names.index(f["right"]), int(up)

    def predictors(self, k: int, retarget: bool = False) -> dict:
        """Returns the method's jitted predictors at `k` by name (cached); `retarget`: each on other proportions (`retargeted`)."""
        if (k, retarget) not in self._fns:
            try:
                fns = self.method.predictors(self.config, self.dataset, self.params, k)
            except KeyError as e:
                raise CheckpointError(f"{self.run_dir}: stage {e.args[0]!r} has no checkpoint; train it first") from None
            if retarget:
                if self.bone_lengths is None:
                    raise UsageError(f"{self.run_dir}: the model has no skeleton to retarget onto (a marker model, or a run "
                                     "trained before predictor.json held bone lengths)")
                blend = round(RETARGET_BLEND_S * self.layout["fps"])
                # A baseline (zero-velocity) is kept as it is: it is what the blended futures are measured against.
                fns = {name: retargeted(fn, self.bone_lengths, self.skeleton.parents, self.facing,
                                        0 if name in self.method.deterministic else blend) for name, fn in fns.items()}
            self._fns[(k, retarget)] = fns
        return self._fns[(k, retarget)]

    @property
    def methods(self) -> list[str]:
        """Returns the predictor names available at the default K (a per-K network, like DLow's, exists only for the trained K)."""
        return sorted(self.predictors(self.default_k))

    def main_method(self, k: int | None = None) -> str:
        """Returns the method's own predictor name (else the last one listed that is not a baseline such as zero-velocity)."""
        fns = self.predictors(k or self.default_k)
        learned = [n for n in fns if n not in self.method.deterministic]
        return self.config.method if self.config.method in fns else (learned or list(fns))[-1]

    def predict(
        self, x, k: int | None = None, key: jax.Array | None = None, method: str | None = None, *, retarget: bool = False,
    ) -> np.ndarray:
        """Returns `(K, t_pred, D)` futures for `x` `(t_his, D)`, or `(b, K, t_pred, D)` for `(b, t_his, D)`.

        Args:
            x: observed frames as `layout` describes them: `(t_his, D)` or `(b, t_his, D)`, metres,
                root-relative with the root dropped (`D = (J - 1) * 3`), finite.
            k: the number of futures K (default: the config's largest evaluated K).
            key: a `jax.random` key (default `jax.random.key(0)`: the same futures every call).
            method: the predictor (default: the run's own; `methods` lists the others, e.g. its CVAE
                sampled from N(0, I)).
            retarget: for a body of other proportions than the training data's (`retargeted`): the model
                sees `x` on its own skeleton, and the futures come back on the bones of `x`'s last frame.

        Returns:
            numpy float32 futures, `(K, t_pred, D)` or `(b, K, t_pred, D)`, in the frames of `x`.

        Raises:
            ValueError: `x` has the wrong shape or holds NaN / inf.
            jaxmotion.errors.UsageError: `k < 1`, or `method` is not available at that K.
            jaxmotion.errors.CheckpointError: the futures are not finite (nothing is returned).
        """
        k = self.default_k if k is None else k
        x = np.asarray(x, np.float32)
        single = x.ndim == 2
        xb = x[None] if single else x
        if xb.ndim != 3 or xb.shape[1:] != (self.t_his, self.dim):
            raise ValueError(f"predict: x must be (t_his={self.t_his}, D={self.dim}) or (b, {self.t_his}, {self.dim}), got {x.shape}")
        if not np.all(np.isfinite(xb)):
            raise ValueError("predict: x holds NaN or inf")
        if k < 1:
            raise UsageError(f"predict: k (the number of futures) must be >= 1, got {k}")
        fns = self.predictors(k, retarget)
        method = method or self.main_method(k)
        if method not in fns:
            raise UsageError(
                f"predict: method {method!r} at K={k} is not available; available: {sorted(fns)} (a per-K network "
                f"such as DLow's exists for the trained K in {tuple(self.config.eval_k)})"
            )
        out = np.asarray(fns[method](jnp.asarray(xb), jax.random.key(0) if key is None else key))
        if not np.isfinite(out).all():  # never handed on (or written) as if they were futures
            raise CheckpointError(
                f"{self.run_dir}: the {method!r} futures of this input hold NaN or inf (the run's parameters are broken, "
                "or the input is far outside what it was trained on); nothing was written"
            )
        return out[0] if single else out


# How long a retargeted future takes to blend from the observed motion into the model's own (`inertialized`):
# chosen on the validation windows of Bandai-Namco-2 among 0, 0.27, 0.5, 1, 1.5 and 2 s
# (experiments/results/retarget_blend.md).
RETARGET_BLEND_S = 1.0


def inertialized(futures: jax.Array, x: jax.Array, frames: int) -> jax.Array:
    """Returns `futures` `(b, K, t_pred, D)` shifted so that their first frame continues `x` `(b, t_his, D)` at its
    last velocity, the shift fading out over `frames` frames (a half cosine), as inertialization blends an
    animation transition; `frames = 0` returns `futures` unchanged."""
    if frames <= 0:
        return futures
    target = 2 * x[:, -1] - x[:, -2] if x.shape[1] > 1 else x[:, -1]  # (b, D): the next frame at constant velocity
    t = jnp.arange(futures.shape[2], dtype=futures.dtype)
    w = jnp.where(t < frames, 0.5 * (1 + jnp.cos(jnp.pi * t / frames)), 0.0)  # 1 at the first frame, 0 from `frames` on
    return futures + w[None, None, :, None] * (target[:, None, None] - futures[:, :, :1])


def retargeted(fn, lengths: np.ndarray, parents: tuple[int, ...], facing: tuple[float, int, int, int] | None = None,
               blend: int = 0):
    """Returns `fn` (a predictor, `(b, t_his, D), key -> (b, K, t_pred, D)`) for bodies of other proportions, jitted.

    `blend`: the futures start from the observed motion and blend into the model's own over that many frames
    (`inertialized`). The observed frames are put on the model's skeleton (every bone the direction it has in the input and
    the length `lengths`, the training data's; a bone of zero length borrows its child's direction,
    `bones.with_bone_lengths`) and, with `facing` (`MotionPredictor.facing`), turned about the up axis so
    that the last observed frame faces the way the training data mostly does, before `fn` sees them. The
    futures are turned back and put on the bones of each window's last observed frame (a bone after one of zero
    length there spans the model's bones it replaces). A model trained on
    one set of actors otherwise reads other proportions as a pose, and answers on its own actors'
    proportions: the first predicted frame then jumps away from the last observed one.
    """
    from jaxmotion.body.bones import bone_lengths, with_bone_lengths

    lengths = jnp.asarray(lengths, jnp.float32)

    def turn(frames, angle):  # (b, ..., D) turned by `angle` (b,) radians about the up axis
        if facing is None:
            return frames
        up = facing[3]
        a_axis, b_axis = (up + 1) % 3, (up + 2) % 3
        j = frames.reshape(frames.shape[:-1] + (-1, 3))
        c, s = (f(angle).reshape((-1,) + (1,) * (j.ndim - 2)) for f in (jnp.cos, jnp.sin))
        a, b = j[..., a_axis], j[..., b_axis]
        j = j.at[..., a_axis].set(a * c - b * s).at[..., b_axis].set(a * s + b * c)
        return j.reshape(frames.shape)

    def hip_angle(last):  # (b, D) -> (b,) radians, as `manifest.facing_angle` measures it on joints
        joints = jnp.concatenate([jnp.zeros(last.shape[:-1] + (1, 3)), last.reshape(last.shape[:-1] + (-1, 3))], axis=-2)
        v = joints[..., facing[2], :] - joints[..., facing[1], :]
        return jnp.arctan2(v[..., (facing[3] + 2) % 3], v[..., (facing[3] + 1) % 3])

    @jax.jit
    def predict(x, key):
        own = bone_lengths(x[:, -1], parents)  # (b, J - 1)
        turned = jnp.radians(facing[0]) - hip_angle(x[:, -1]) if facing is not None else jnp.zeros(x.shape[0])
        seen = turn(with_bone_lengths(x, lengths, parents, borrow_direction=True), turned)
        futures = inertialized(fn(seen, key), seen, blend)
        return with_bone_lengths(turn(futures, -turned), own[:, None, None], parents, span_zero_bones=True)

    return predict


def load(run_dir: str | Path, stages: tuple[str, ...] | None = None) -> MotionPredictor:
    """Returns a trained model as a `MotionPredictor`: a run directory, an exported file (`export`) or a shipped model's name.

    `stages` restores only those stages of a run directory (a CheckpointError names any without a
    checkpoint): e.g. a GSPS run's `("prior", "angle_bounds")` for `validity.from_gsps_run`, before its
    generator is trained. `PRETRAINED` lists the shipped models (`jaxmotion predict --model bandai`).
    """
    path = Path(run_dir)
    if str(run_dir) in PRETRAINED and not path.exists():
        path = pretrained_path(str(run_dir))
    if path.is_file():
        if stages is not None:
            raise ValueError(f"load: {path} is an exported model; it holds every stage (stages= is for run directories)")
        return read_model(path)
    if not path.exists() and not path.suffix and "/" not in str(run_dir):
        raise FileNotFoundError(f"{run_dir}: no such run directory, exported model or shipped model (shipped: {sorted(PRETRAINED)})")
    return MotionPredictor(path, stages)


# ----------------------------------------------------------------------------------------------
# Exported models: one file with the parameters (no optimiser state) and what predictor.json holds.

EXPORT_FORMAT = "jaxmotion-model"
PRETRAINED_DIR = Path(__file__).resolve().parent.parent / "pretrained"


def shipped_models() -> dict:
    """Returns `jaxmotion/pretrained/models.json`: every shipped model (file, method, data, licence, size, metrics), the
    default's name and the rule that chose it. Its model cards (`pretrained/README.md`) are generated from it."""
    return json.loads((PRETRAINED_DIR / "models.json").read_text())


def _pretrained() -> dict[str, str]:
    reg = shipped_models()
    files = {m["name"]: m["file"] for m in reg["models"]}
    return {"bandai": files[reg["default"]], **files}


# Shipped models: name -> file in jaxmotion/pretrained/; "bandai" is the default one (`shipped_models`).
PRETRAINED = _pretrained()


def pretrained_path(name: str) -> Path:
    """Returns the file of the shipped model `name` (`PRETRAINED`)."""
    if name not in PRETRAINED:
        raise FileNotFoundError(f"{name}: not a shipped model (shipped: {sorted(PRETRAINED)})")
    path = PRETRAINED_DIR / PRETRAINED[name]
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the shipped model {name!r} is missing from this installation")
    return path


def export(
    run_dir: str | Path, out: str | Path, stages: tuple[str, ...] | None = None, *, float16: bool = False,
    manifest: dict | None = None,
) -> Path:
    """Writes the trained run at `run_dir` as one inference-only file (msgpack: predictor.json's contents, the parameters
    of every stage, or of `stages`, and their shapes) and returns its path; `load` and `jaxmotion predict` accept it.

    `float16`: float32 parameters are stored as float16 (half the file; `read_model` turns them back into
    float32). `manifest`: entries added to the run's predictor.json contents (e.g. a `facing` measured after training).
    """
    from flax import serialization

    from jaxmotion.train.runner import param_shapes

    model = MotionPredictor(run_dir, stages)
    params = {stage: jax.tree.map(np.asarray, p) for stage, p in model.params.items()}
    shapes = {stage: param_shapes(p) for stage, p in params.items()}
    if float16:
        params = jax.tree.map(lambda v: v.astype(np.float16) if v.dtype == np.float32 else v, params)
    payload = {
        "format": EXPORT_FORMAT, "version": VERSION, "predictor": json.dumps({**model.manifest, **(manifest or {})}),
        "shapes": json.dumps(shapes), "params": params, "storage": "float16" if float16 else "as trained",
    }
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_bytes(serialization.msgpack_serialize(payload))
    tmp.replace(out)
    return out


def read_model(path: str | Path) -> MotionPredictor:
    """Returns the `MotionPredictor` of an exported file (`export`); `CheckpointError` if it is not one or is damaged."""
    from flax import serialization

    from jaxmotion.train.runner import param_shapes

    path = Path(path)
    try:
        payload = serialization.msgpack_restore(path.read_bytes())
    except Exception as e:  # msgpack raises several types on a truncated or foreign file
        raise CheckpointError(f"{path}: not an exported jaxmotion model ({type(e).__name__}: {e})") from None
    if not isinstance(payload, dict) or payload.get("format") != EXPORT_FORMAT:
        raise CheckpointError(f"{path}: not an exported jaxmotion model (jaxmotion export RUN --out FILE writes one)")
    params = {stage: jax.tree.map(jnp.asarray, p) for stage, p in payload["params"].items()}
    if payload.get("storage") == "float16":  # stored at half size (`export(float16=True)`), computed in float32
        params = jax.tree.map(lambda v: v.astype(jnp.float32) if v.dtype == jnp.float16 else v, params)
    if json.loads(payload["shapes"]) != {stage: param_shapes(p) for stage, p in params.items()}:
        raise CheckpointError(f"{path}: its parameters do not match the shapes it lists (damaged file?)")
    return MotionPredictor.from_parts(json.loads(payload["predictor"]), params, path)
