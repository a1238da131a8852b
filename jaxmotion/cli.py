"""The `jaxmotion` command: `run`, `train`, `eval`, `sample`, `methods`, `models`, `predict`, `export`, `view`.

Examples (`jaxmotion COMMAND --help` lists every option):

```text
jaxmotion run                                   # synthetic data -> CVAE -> DLow -> metrics + PNG
jaxmotion run --config experiments/configs/dlow_bandai.py --data ../shared/data/bandai-namco-2
jaxmotion train --config CFG [--data PATH] [--workdir DIR] [--resume]
jaxmotion train --config CFG --coordinator-address HOST:PORT --num-processes N --process-id I   # in each of N processes
jaxmotion eval --config CFG [--data PATH] [--workdir DIR]
jaxmotion eval --model bandai --data MY_BVH_FOLDER [--workdir DIR]   # a shipped or trained model, every clip a test clip
jaxmotion sample --config CFG [--workdir DIR] --window 3 --k 50 --method dlow
jaxmotion sample --config experiments/configs/gsps_synthetic.py --window 208 --fix-part lower   # one lower body, 10 upper bodies
jaxmotion methods                               # the registered methods and their stages' settings type
jaxmotion models                                # the shipped models: size, data, licence, metrics
jaxmotion predict --model bandai clip.bvh --out DIR     # your own motion, the shipped model (no training)
jaxmotion predict RUN_DIR --input clip.bvh [--frame F] [--k K] [--method M] [--joint-map FILE] --out DIR
jaxmotion export RUN_DIR --out model.msgpack             # one inference-only file for load / predict --model
jaxmotion view RUN_DIR [--out FILE.html] [--windows N] [--k K] [--method M]   # a 3-D viewer page (plotly)
```
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import NoReturn

from jaxmotion.errors import CheckpointError, ConfigError, DataError, RunFolderError, UsageError

# What a user can cause and fix, each with a message naming the file, folder, field or option: printed as
# one line, exit code 2 (`entry`). OSError: a missing file, a read-only folder, a full disk.
USER_ERRORS = (DataError, ConfigError, CheckpointError, RunFolderError, UsageError, OSError)


# Every integer option's upper end: a count past it is no count of windows, futures or frames (and would
# overflow a C long inside numpy or jax); seeds have their own (`config.SEED_LIMIT`).
INT_LIMIT = 2**31 - 1


def _int_at_least(low: int, high: int = INT_LIMIT):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not low <= v <= high:
            raise argparse.ArgumentTypeError(f"must be in [{low}, {high}], got {v}")
        return v

    parse.__name__ = f"integer in [{low}, {high}]"
    return parse


def _seed(text: str) -> int:
    from jaxmotion.config import SEED_LIMIT

    return _int_at_least(0, SEED_LIMIT - 1)(text)


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jaxmotion", description="Stochastic 3D human motion prediction in JAX.")
    sub = p.add_subparsers(dest="command", required=True)
    for name, help_ in [
        ("run", "train every stage, evaluate and write a report (the main job)"),
        ("train", "train the CVAE and the DLow Q networks"),
        ("eval", "evaluate trained checkpoints under the protocol; writes metrics.json and samples.png"),
        ("sample", "draw K futures for one test window; writes an .npz and a PNG"),
    ]:
        s = sub.add_parser(name, help=help_)
        s.add_argument("--config", default=None, help="Python config file defining get_config() (default: built-in synthetic job)")
        s.add_argument("--data", default=None, help="'synthetic', a BVH folder, the Bandai-Namco-2 folder, or an H36M/HumanEva .npz")
        s.add_argument("--workdir", default=None, help="output directory (default: runs/<config name>)")
        s.add_argument("--seed", type=_seed, default=None, help="override the config's seed (initialisation, batches, evaluation draws)")
        s.add_argument("--test-files", nargs="+", default=None, metavar="PATTERN",
                       help="a plain BVH folder's test files (glob patterns on path, name or stem); default: by subject, else the last 20%% of files")
        s.add_argument("--precision", choices=("float32", "bf16"), default=None,
                       help="override the config's matrix-product precision (Config.precision): bf16 = bfloat16 operands, "
                            "float32 accumulation; faster only on CPUs with bfloat16 instructions")
        s.add_argument("--scale", nargs="+", default=None, metavar="S|PATTERN=S",
                       help="a plain BVH folder's metres per file unit: one number for every file, or PATTERN=S per file "
                            "(glob on path, name or stem; files no pattern matches are guessed). Default: each file's own, guessed")
        if name in ("run", "train"):
            s.add_argument("--resume", action="store_true", help="continue from the latest checkpoints in --workdir")
        if name in ("run", "train", "eval"):
            _distributed_flags(s)
        if name == "eval":
            g = s.add_argument_group("a trained or shipped model on your own folder (every clip a test clip)")
            g.add_argument("--model", default=None, help="a shipped model ('bandai'), an exported file or a run directory; "
                                                         "--data is then a folder of BVH clips, all of them test clips")
            g.add_argument("--joint-map", default=None, metavar="FILE", help='JSON {"model joint": "file joint"} (default: names, else a built-in map)')
            g.add_argument("--k", type=_int_at_least(1), default=None, help="number of futures (default: the model's largest K)")
            g.add_argument("--no-retarget", action="store_true",
                           help="show the model each clip on its own proportions (default: on the model's skeleton, futures back on the clip's bones)")
        if name == "sample":
            s.add_argument("--window", type=_int_at_least(0), default=0, help="test window index")
            s.add_argument("--k", type=_int_at_least(1), default=None, help="number of futures (default: largest K of the config; 10 with --fix-part)")
            s.add_argument("--method", default=None, help="which sampler (default: the config's method; also cvae, zero_velocity)")
            s.add_argument("--fix-part", nargs="+", default=None, metavar="PART",
                           help="body-part control (GSPS): hold these parts' noise (lower | upper; with GSPSConfig.parts='five': "
                                "torso right_leg left_leg right_arm left_arm) and vary the rest. The first part predicted "
                                "(lower) is then identical across the K samples; a later one still follows the varying earlier parts")
    sub.add_parser("methods", help="list the registered methods")
    sub.add_parser("models", help="list the shipped models: size, data, licence, metrics (jaxmotion/pretrained/README.md has their cards)")
    s = sub.add_parser("predict", help="K futures of your own clip (BVH or npz of joint positions) from a trained or shipped model")
    s.add_argument("paths", nargs="*", metavar="[RUN_DIR] CLIP",
                   help="a trained work directory or exported model file, then the clip (without --model); the clip (with --model)")
    s.add_argument("--model", default=None, help="a shipped model ('bandai': DLow on Bandai-Namco-2), an exported file, or a run directory")
    s.add_argument("--input", default=None, help="the clip: a .bvh clip, an .npz with 'positions' (T, J, 3) [, 'names', 'fps', 'scale'], or a .c3d marker file (marker models)")
    s.add_argument("--frame", type=_int_at_least(0), default=None,
                   help="input frame that ends the observed window (default: the last one whose whole future is in the clip, else the last frame)")
    s.add_argument("--k", type=_int_at_least(1), default=None, help="number of futures (default: the run's largest K)")
    s.add_argument("--method", default=None, help="which predictor (default: the run's method)")
    s.add_argument("--scale", type=_positive_float, default=None, help="metres per file unit (default: guessed for BVH, 1 for npz)")
    s.add_argument("--joint-map", default=None, metavar="FILE",
                   help='JSON {"model joint": "file joint"} (default: same names, else a built-in map: CMU, Mixamo, LAFAN1, SMPL, Bandai-Namco)')
    s.add_argument("--seed", type=_seed, default=0, help="seed of the sampling key")
    s.add_argument("--no-retarget", action="store_true",
                   help="show the model the clip on its own proportions (default: on the model's skeleton, futures back on the clip's bones)")
    s.add_argument("--out", required=True, help="output folder: futures.npz, future_NN.bvh, samples.gif")
    s = sub.add_parser("export", help="write a trained run as one inference-only model file (for jaxmotion.load and predict --model)")
    s.add_argument("run_dir", help="a trained work directory (with predictor.json)")
    s.add_argument("--out", required=True, help="the model file to write (e.g. model.msgpack)")
    s.add_argument("--stages", nargs="+", default=None, help="only these stages (default: all), e.g. cvae: DLow's sampler without its Q networks")
    s.add_argument("--float16", action="store_true", help="store the parameters as float16 (half the file; computed in float32)")
    s = sub.add_parser("view", help="one self-contained HTML page to browse test windows and their K futures in 3-D (needs plotly)")
    s.add_argument("run_dir", nargs="?", default=None, help="a trained work directory (default: --workdir, else runs/<config name>)")
    s.add_argument("--config", default=None, help="config file that rebuilds the test windows (default: the run's own, from predictor.json)")
    s.add_argument("--data", default=None, help="the dataset (default: the one the run was trained on)")
    s.add_argument("--workdir", default=None, help="the trained work directory, as for sample (same as RUN_DIR)")
    s.add_argument("--test-files", nargs="+", default=None, metavar="PATTERN", help="a plain BVH folder's test files, as for sample")
    s.add_argument("--out", default=None, help="the HTML file (default: RUN_DIR/view.html)")
    s.add_argument("--windows", type=_int_at_least(1), default=6, help="how many test windows, the most multimodal first (default 6)")
    s.add_argument("--k", type=_int_at_least(1), default=10, help="futures per window (default 10)")
    s.add_argument("--method", default=None, help="which predictor (default: the run's method)")
    s.add_argument("--seed", type=_seed, default=0, help="seed of the sampling key")
    s.add_argument("--keep-skeleton", action="store_true",
                   help="put each future on its window's observed bone lengths (as predict writes them); default: the model's output")
    return p


def _distributed_flags(s: argparse.ArgumentParser) -> None:
    g = s.add_argument_group("many processes", "jax.distributed: run the same command in every process (docs/pages/distributed.md)")
    g.add_argument("--distributed", action="store_true",
                   help="start jax.distributed; the settings below that are not given are detected (SLURM, Open MPI, Cloud TPU)")
    g.add_argument("--coordinator-address", default=None, metavar="HOST:PORT", help="process 0's address (default: $JAX_COORDINATOR_ADDRESS)")
    g.add_argument("--num-processes", type=_int_at_least(1), default=None, metavar="N", help="number of processes (default: $JAX_NUM_PROCESSES)")
    g.add_argument("--process-id", type=_int_at_least(0), default=None, metavar="I", help="this process, 0 .. N-1 (default: $JAX_PROCESS_ID)")
    s.add_argument("--host-devices", type=_int_at_least(1, 256), default=None, metavar="N",
                   help="on a CPU: split every step over N host devices of this process (XLA's forced host device count), "
                        "each a stream of XLA operations of its own; the run's numbers are the one-device run's to float32 "
                        "rounding (docs/pages/distributed.md)")


def _list_methods() -> int:
    from jaxmotion.methods import methods

    for name, m in methods().items():
        t = m.config_type
        print(f"{name:<10s} {t.__module__}.{t.__name__:<14s} {m.description}")
    return 0


def _list_models() -> int:
    from jaxmotion.tools.predictor import shipped_models

    reg = shipped_models()
    print(f"{'name':<16s} {'method':<8s} {'MB':>5s}  {'val ADE':>7s}  {'test ADE / FDE':>14s}  {'CMU ADE / FDE / FFE':>20s}  "
          f"{'CMU zero-velocity':>20s}")
    for m in reg["models"]:
        met = m["metrics"]
        three = lambda d, ks: " / ".join(f"{d[k]:.3f}" for k in ks) if d else "-"  # noqa: E731
        print(f"{m['name']:<16s} {m['method']:<8s} {m['size_bytes'] / 1e6:5.1f}  {three(met.get('validation'), ['ADE']):>7s}  "
              f"{three(met.get('test'), ['ADE', 'FDE']):>14s}  {three(met.get('cmu'), ['ADE', 'FDE', 'FFE']):>20s}  "
              f"{three(met.get('cmu_zero_velocity'), ['ADE', 'FDE', 'FFE']):>20s}"
              + ("  (default: --model bandai)" if m["name"] == reg["default"] else ""))
    print(f"default: {reg['default']}, chosen by {reg['rule']}")
    print(f"data: {reg['data']}")
    print(f"licence: {reg['licence']}")
    print("metres, K = 50; cards: jaxmotion/pretrained/README.md")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Runs one command; a user's mistake is raised as one of `USER_ERRORS` (`predict` and `view` print it
    and return 2), for `entry` to print as one line."""
    args = _parser().parse_args(argv)
    if args.command == "methods":
        return _list_methods()
    if args.command == "models":
        return _list_models()
    if args.command == "predict":
        return _predict(args)
    if args.command == "export":
        from jaxmotion.tools.predictor import export

        try:
            path = export(args.run_dir, args.out, tuple(args.stages) if args.stages else None, float16=args.float16)
        except USER_ERRORS as e:
            return _report(e, "jaxmotion export")
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): jaxmotion predict --model {path} CLIP --out DIR")
        return 0
    if args.command == "view":
        return _view(args)
    if args.command == "eval" and args.model is not None:
        return _eval_model(args)
    host_devices = getattr(args, "host_devices", None)
    from jaxmotion.train.host_devices import check_host_devices, force_host_devices  # imports no jax

    if host_devices is not None:  # before anything runs on a device: XLA reads the flag as jax's backend starts
        force_host_devices(host_devices)
    from jaxmotion.train import distributed

    if args.command in ("run", "train", "eval"):  # before anything runs on a device
        distributed.initialize(args.coordinator_address, args.num_processes, args.process_id, auto=args.distributed)
    if host_devices is not None:
        check_host_devices(host_devices)
    from jaxmotion.config import load_config

    cfg = load_config(args.config)
    source = args.config or "the default config"
    if getattr(args, "scale", None) is not None:
        cfg = _with_scale(cfg, args.scale, args.data)
    cfg = _with_overrides(cfg, args, source)
    part_control = _part_control(cfg, args.method) if args.command == "sample" and args.fix_part else None
    workdir = Path(args.workdir or Path("runs") / cfg.name).absolute()
    from jaxmotion.train.run_lock import run_lock

    # One process at a time in a run folder (process 0 of a distributed job holds it for all).
    with run_lock(workdir, args.command) if distributed.is_main() else contextlib.nullcontext():
        return _run(args, cfg, workdir, part_control, source)


def _with_overrides(cfg, args, source: str):
    """Returns the config with --seed / --precision applied, checked, and its method's settings filled in."""
    import dataclasses

    from jaxmotion import experiment
    from jaxmotion.config import validate

    if args.seed is not None or args.precision is not None:
        cfg = dataclasses.replace(cfg, seed=cfg.seed if args.seed is None else args.seed,
                                  precision=args.precision or cfg.precision)
        validate(cfg, source=source)
    try:
        return experiment.resolve(cfg)
    except (TypeError, ValueError) as e:  # an unknown method, settings of another method's type
        raise ConfigError(source, [str(e)]) from None


def _run(args, cfg, workdir: Path, part_control, source: str) -> int:
    from jaxmotion import experiment
    from jaxmotion.train import distributed
    from jaxmotion.config import check_memory, validate

    t0 = time.perf_counter()
    try:
        ds = experiment.load_data(cfg, args.data, args.test_files)
    except USER_ERRORS:
        raise
    except ValueError as e:  # a loader refusing an option: data_options or --test-files
        raise ConfigError(source, [f"data_options {cfg.data_options} / --data / --test-files: {e}"]) from None
    prep = experiment.prepare(ds, cfg.max_test_windows, cfg.train_sampler)
    validate(cfg, prep.sampler.num_windows, source=source)
    check_memory(cfg, ds.dim, ds.t_his, ds.t_pred, source=source)  # before any step is trained
    label = ds.name
    print(
        f"data: {ds.name}: {len(ds.train)} train / {len(ds.test)} test sequences, D={ds.dim}, "
        f"{ds.t_his}->{ds.t_pred} frames at {round(ds.fps, 2):g} fps, {prep.sampler.num_windows} train windows, "
        f"{len(prep.windows)} test windows ({time.perf_counter() - t0:.1f}s)",
        flush=True,
    )
    if "split" in ds.info:
        print(f"split: {ds.info['split']}", flush=True)
    if args.command in ("run", "train"):
        params = experiment.train(cfg, prep, workdir, resume=args.resume)
    else:
        params = experiment.restore(cfg, prep, workdir)
    if args.command in ("run", "eval") and not distributed.is_main():
        # Its devices predict their share of the test windows; process 0 writes the metrics and pictures.
        with tempfile.TemporaryDirectory() as scratch, contextlib.redirect_stdout(io.StringIO()):
            experiment.evaluate(cfg, prep, params, Path(scratch), label)
    elif args.command in ("run", "eval"):
        experiment.evaluate(cfg, prep, params, workdir, label)
        png = experiment.report(cfg, prep, params, workdir)
        print(f"report: {workdir}  (metrics.json, {png.name}, samples.gif, predictor.json, checkpoints)  total {time.perf_counter() - t0:.0f}s")
    elif args.command == "sample":
        import jax
        import jax.numpy as jnp
        import numpy as np

        from jaxmotion.formats.atomic import savez_atomic
        from jaxmotion.pictures.viz import plot_futures

        if not 0 <= args.window < len(prep.windows):
            raise UsageError(f"--window must be in [0, {len(prep.windows)}), got {args.window}")
        if part_control is not None:
            print(_sample_fixed_parts(part_control, cfg, prep, params, args.window, args.k or 10, tuple(args.fix_part), workdir, label))
            return 0
        k = args.k or max(cfg.eval_k)
        args.method = args.method or cfg.method
        fns = experiment.predictors(cfg, ds, params, k)
        if args.method not in fns:
            raise SystemExit(f"--method {args.method} --k {k}: available here: {sorted(fns)} (a method with one network per K, like DLow, was trained for K in {cfg.eval_k})")
        fn = fns[args.method]
        i = args.window
        preds = np.asarray(fn(jnp.asarray(prep.x[i : i + 1]), jax.random.key(cfg.seed)))[0]
        out = workdir / f"sample_w{i}_{args.method}_k{k}"
        savez_atomic(out.with_suffix(".npz"), x=prep.x[i], y=prep.y[i], preds=preds)
        plot_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, out.with_suffix(".png"),
                     title=f"{label}: window {i}, {args.method}, K={k}")
        print(f"wrote {out}.npz and {out}.png")
    else:
        print(f"checkpoints: {workdir}  total {time.perf_counter() - t0:.0f}s")
    return 0


def _with_scale(cfg, values: list[str], data: str | None):
    """Returns `cfg` with `--scale` in its data options (`data.units.parse_scale`); exits if the data is not a plain BVH folder."""
    import dataclasses

    from jaxmotion.data.units import parse_scale
    from jaxmotion.experiment import plain_bvh_folder

    spec = data or cfg.dataset
    if not plain_bvh_folder(Path(spec).expanduser()):
        raise SystemExit(f"--scale applies to a plain folder of BVH files; {spec} is not one (its loader knows its units)")
    try:
        scale = parse_scale(values)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    return dataclasses.replace(cfg, data_options={**cfg.data_options, "scale": scale})


def _eval_model(args) -> int:
    """`jaxmotion eval --model M --data FOLDER`: every clip of the folder a test clip (`jaxmotion.tools.evaluate_folder`)."""
    from jaxmotion.data.units import parse_scale
    from jaxmotion.tools.evaluate_folder import evaluate_folder
    from jaxmotion.tools.joint_maps import read_joint_map
    from jaxmotion.tools.predictor import load

    if args.data is None or args.config is not None:
        raise SystemExit("jaxmotion eval --model M: give the folder of clips with --data FOLDER (and no --config: the model has one)")
    workdir = Path(args.workdir or Path("runs") / f"eval_{Path(args.data).name}")
    try:
        scale = parse_scale(args.scale)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    joint_map = read_joint_map(args.joint_map) if args.joint_map else None
    lines = evaluate_folder(load(args.model), args.data, workdir, k=args.k, scale=scale, joint_map=joint_map, seed=args.seed,
                            retarget=not args.no_retarget)
    print("\n".join(lines))
    return 0


def _predict(args) -> int:
    """`jaxmotion predict`: the model from --model or the first path, the clip from --input or the last path."""
    from jaxmotion.tools.joint_maps import read_joint_map
    from jaxmotion.tools.predict_file import predict_file
    from jaxmotion.tools.predictor import load

    paths = list(args.paths)
    model = args.model if args.model is not None else (paths.pop(0) if paths else None)
    clip = args.input if args.input is not None else (paths.pop(0) if paths else None)
    if model is None or clip is None or paths:
        raise SystemExit("jaxmotion predict: give a model (--model NAME|FILE, or a run directory) and one clip, e.g. "
                         "jaxmotion predict --model bandai clip.bvh --out futures/")
    try:
        joint_map = read_joint_map(args.joint_map) if args.joint_map else None
        lines = predict_file(load(model), clip, args.out, frame=args.frame, k=args.k, method=args.method,
                             seed=args.seed, scale=args.scale, joint_map=joint_map, retarget=not args.no_retarget)
    except USER_ERRORS as e:  # the user's file or run: the message says it all
        return _report(e, "jaxmotion predict")
    print("\n".join(lines))
    return 0


def _view(args) -> int:
    """`jaxmotion view`: writes the page (`jaxmotion.tools.viewer.view_run`); a bad run, file or option is one line, exit code 2."""
    run_dir = args.run_dir or args.workdir
    if args.run_dir and args.workdir and Path(args.run_dir).absolute() != Path(args.workdir).absolute():
        raise UsageError(f"RUN_DIR {args.run_dir} and --workdir {args.workdir} differ; give one")
    if run_dir is None:
        from jaxmotion.config import load_config

        run_dir = Path("runs") / load_config(args.config).name
    try:
        from jaxmotion.tools.viewer import view_run

        lines = view_run(run_dir, args.out, windows=args.windows, k=args.k, method=args.method, seed=args.seed,
                         config=args.config, data=args.data, test_files=args.test_files, keep_skeleton=args.keep_skeleton)
    except ModuleNotFoundError as e:
        if e.name != "plotly":
            raise
        return _report(e, "jaxmotion view")
    except (*USER_ERRORS, ValueError) as e:  # the user's run or options: the message says it all
        return _report(e, "jaxmotion view")
    print("\n".join(lines))
    return 0


def _part_control(cfg, method: str | None):
    """Returns the config's method's part-control sampler (`Method.part_control`); exits with the reason when there is none."""
    from jaxmotion.methods import get_method, methods

    m = get_method(cfg.method)
    if m.part_control is None:
        have = sorted(n for n, x in methods().items() if x.part_control is not None)
        raise SystemExit(f"--fix-part: method {cfg.method!r} has no body-part control (methods that have: {', '.join(have)})")
    if method not in (None, cfg.method):
        raise SystemExit(f"--fix-part samples the run's own method ({cfg.method}), not --method {method}")
    return m.part_control


def _sample_fixed_parts(part_control, cfg, prep, params, i: int, k: int, fix: tuple[str, ...], workdir: Path, label: str) -> str:
    """Writes K part-controlled futures of test window `i` (.npz and a `viz.plot_futures` PNG); returns what it wrote and held."""
    import jax
    import numpy as np

    from jaxmotion.formats.atomic import savez_atomic
    from jaxmotion.pictures.viz import plot_futures

    ds = prep.dataset
    try:
        preds = np.asarray(part_control(cfg, ds, params, prep.x[i : i + 1], jax.random.key(cfg.seed), k, fix))[0]
    except ValueError as e:  # an unknown part name: the message lists the valid ones
        raise SystemExit(f"--fix-part: {e}") from None
    spread = preds.reshape(k, ds.t_pred, -1, 3).std(axis=0).max(axis=(0, 2))  # per joint (root dropped), m
    held = spread < 1e-5  # identical up to float32 rounding
    out = workdir / f"sample_w{i}_{cfg.method}_k{k}_fix-{'-'.join(fix)}"
    savez_atomic(out.with_suffix(".npz"), x=prep.x[i], y=prep.y[i], preds=preds, fix=np.asarray(fix), joint_spread=spread)
    plot_futures(prep.x[i], preds, prep.y[i], ds.skeleton.parents, out.with_suffix(".png"),
                 title=f"{cfg.method} part control: {', '.join(fix)} held, the rest varies ({label}: test window {i}, K={k})")
    names = [n for n, h in zip(ds.skeleton.names[1:], held) if h]
    return (f"wrote {out}.npz and {out}.png\n{len(names)} of {len(held)} joints identical across the {k} samples"
            f"{': ' + ', '.join(names) if names else ''}; the others' std over the samples is up to "
            f"{spread[~held].max() if (~held).any() else 0.0:.3f} m")


class _LateLoopTracebacksDropped:
    """Stderr without the "RuntimeError: Event loop is closed" tracebacks of tensorstore's late reads.

    When one array of a checkpoint fails to read, orbax's restore raises and closes its event loop,
    but tensorstore finishes the other reads it started and hands each result to that closed loop
    (`call_soon_threadsafe`); each prints a traceback from tensorstore's threads, 5-16 for a DLow run,
    before and after the error's one line, several threads at once. Nobody waits for those reads. Each
    thread's traceback is held from its header to its exception line, and dropped only when it is
    that one; everything else passes.
    """

    _HEADER = "Traceback (most recent call last):"

    def __init__(self, stream):
        import threading

        self.stream, self._lock, self._held = stream, threading.Lock(), {}  # thread id -> its traceback so far

    def write(self, s: str) -> int:
        import threading

        me = threading.get_ident()
        with self._lock:
            held = self._held.get(me)
            if held is None:
                if not s.startswith(self._HEADER):
                    return self.stream.write(s)
                held = ""
            held += s
            lines = held.splitlines()
            last = lines[-1] if held.endswith("\n") else ""
            if last and not last.startswith((" ", self._HEADER)):  # the exception line: the traceback is whole
                del self._held[me]
                if not (last == "RuntimeError: Event loop is closed" and "call_soon_threadsafe" in held):
                    self.stream.write(held)
            else:
                self._held[me] = held
            return len(s)

    def flush(self) -> None:
        self.stream.flush()

    def __getattr__(self, name):  # fileno, isatty, encoding ... of the real stream
        return getattr(self.stream, name)


class _OrbaxThreadErrorsDropped:
    """A `logging` filter dropping the error records whose traceback runs through orbax's code.

    When a checkpoint write fails (a full disk), orbax's writer threads log each failed array with its
    traceback (logger `absl`), and asyncio logs each of their gathered futures again when it is collected
    (logger `asyncio`, "exception was never retrieved"): a hundred lines or more around the one error.
    The same failure reaches `train.loop._save`, which raises it as a `CheckpointError` naming the
    folder, so those records say nothing new. A failed restore leaves such futures too, some holding
    tensorstore's own error with no Python frame at all (its text names a `tensorstore_spec`); the
    restore's error is already the one line, so those are dropped as well. Every other record passes.
    """

    @staticmethod
    def filter(record) -> bool:
        import traceback

        if not record.exc_info or record.exc_info[1] is None:
            return True
        tb = record.exc_info[2]
        if tb is None:
            return "tensorstore_spec" not in str(record.exc_info[1])
        return not any("/orbax/" in f.filename.replace("\\", "/") for f in traceback.extract_tb(tb))


def _report(e: BaseException, prog: str = "jaxmotion") -> int:
    """Prints a user's error as one line on stderr; returns exit code 2."""
    print(f"{prog}: error: {e}", file=sys.stderr, flush=True)
    return 2


def _exit_after_report(code: int) -> NoReturn:
    """Ends the console script at once after a user's error (`os._exit`, the streams flushed first).

    After a failed checkpoint restore, orbax's and tensorstore's leftover futures, coroutines and reader
    threads are collected during the interpreter's shutdown, each printing a line or a traceback after the
    error's one line (asyncio's "exception was never retrieved", "coroutine ... was never awaited", "Event
    loop is closed"). Nothing is being written on this path: the error ended the command, and the files it
    had open were closed as the error passed through them."""
    import os

    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(code)


def entry() -> int:
    """The console script: `main`, with every error a user can cause printed as one line (exit code 2).

    A bad file, config, checkpoint, run folder or option is the user's to fix, and its message names
    what is wrong, so the traceback through jaxmotion's internals is left out (`USER_ERRORS`; a
    `SystemExit` with a message is one too). `main` itself raises them (for tests and for code that
    calls it). Tensorstore's late "Event loop is closed" tracebacks after a failed checkpoint restore
    are dropped (`_LateLoopTracebacksDropped`), and so are orbax's writer threads' logged tracebacks after a
    failed checkpoint write or restore (`_OrbaxThreadErrorsDropped`), and after a user's error the script
    ends at once (`_exit_after_report`), so the message is all a user sees.
    """
    from jaxmotion.train.hugepages import exec_with_hugepages

    exec_with_hugepages()  # once, before anything runs: large XLA buffers in 2 MiB pages (jaxmotion/train/hugepages.py)
    sys.stderr = _LateLoopTracebacksDropped(sys.stderr)
    import logging

    for name in ("absl", "asyncio"):
        logging.getLogger(name).addFilter(_OrbaxThreadErrorsDropped)
    try:
        return main()
    except USER_ERRORS as e:
        return _exit_after_report(_report(e))
    except SystemExit as e:
        if isinstance(e.code, str):
            return _exit_after_report(_report(e.code))
        raise
    except KeyboardInterrupt:
        print("jaxmotion: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(entry())
