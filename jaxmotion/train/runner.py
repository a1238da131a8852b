"""The one stage runner: trains, resumes and restores the stages of any method.

A work directory holds one folder per stage (`WORKDIR/<stage>/ckpt`, `log.jsonl`) and a
`stage.json` beside them naming the method, the stage and the shape of every parameter, so that
restoring a stage from a folder written by another stage or another method is a clear error that
names the stage and the mismatch, not a stack trace from the checkpoint library.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.train import distributed
from jaxmotion.errors import CheckpointError
from jaxmotion.formats.atomic import write_text_atomic
from jaxmotion.method import Method, Stage
from jaxmotion.train import loop
from jaxmotion.train.loop import TrainState, create_state, fit, make_bn_train_step, make_train_step, restore_params

MANIFEST = "stage.json"


class CheckpointMismatch(CheckpointError):
    """A stage folder holds another stage's or another method's checkpoints."""


def init_state(stage: Stage, trained: dict[str, Any] | None = None) -> TrainState:
    """Returns the stage's fresh `TrainState`: `stage.init(key(init_seed))`, its optimiser state, its frozen inputs.

    `trained` maps earlier stage names to their parameters; the stage's `frozen` names must be there.
    """
    trained = trained or {}
    missing = [n for n in stage.frozen if n not in trained]
    if missing:
        raise ValueError(f"stage {stage.name!r} needs the trained parameters of {missing} (train those stages first)")
    frozen = {n: trained[n] for n in stage.frozen}
    params = stage.init(jax.random.key(stage.init_seed), frozen)
    return create_state(params, stage.optimizer, frozen=frozen or None)


def param_shapes(params) -> dict[str, list]:
    """Returns `{key path: [shape, dtype]}` of a parameter pytree (what `stage.json` records)."""
    leaves = jax.tree_util.tree_flatten_with_path(params)[0]
    return {jax.tree_util.keystr(p): [list(v.shape), str(v.dtype)] for p, v in leaves}


def _manifest(method: Method, stage: Stage, state: TrainState, upstream: dict[str, int]) -> dict:
    return {
        "method": method.name, "stage": stage.name, "num_steps": stage.num_steps,
        "upstream": {n: upstream[n] for n in stage.frozen}, "params": param_shapes(state.params),
    }


def check_stage_dir(method: Method, stage: Stage, state: TrainState, stage_dir: Path, upstream: dict[str, int] | None = None) -> None:
    """Raises `CheckpointMismatch` naming the stage and the difference when `stage_dir` was written for another stage.

    `upstream` maps the frozen stages to the step they are trained to: a stage trained on an earlier
    state of them (a resumed run that trained them further) is stale, and is reported, not reused.
    """
    path = stage_dir / MANIFEST
    if not path.exists():
        return
    try:
        found = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CheckpointMismatch(f"stage {stage.name!r}: {path} is unreadable ({e}); it should name the method and stage") from e
    if found.get("method") != method.name or found.get("stage") != stage.name:
        raise CheckpointMismatch(
            f"stage {stage.name!r} of method {method.name!r}: {stage_dir} holds stage {found.get('stage')!r} of method "
            f"{found.get('method')!r}; point --workdir at a run of this config, or train it there"
        )
    want, have = param_shapes(state.params), found.get("params", {})
    if want != have:
        diff = sorted(set(want) ^ set(have))
        if diff:
            what = f"parameters only in {'the config' if diff[0] in want else 'the checkpoint'}: {diff[:4]}"
        else:
            p = next(p for p in sorted(want) if want[p] != have[p])
            what = f"{p} is {have[p][0]} {have[p][1]} in the checkpoint but {want[p][0]} {want[p][1]} for this config"
        raise CheckpointMismatch(
            f"stage {stage.name!r} of method {method.name!r}: the checkpoints in {stage_dir} do not fit this config "
            f"({what}); was the config changed after training?"
        )
    for name, step in (upstream or {}).items():
        was = found.get("upstream", {}).get(name)
        if was is not None and was != step:
            raise CheckpointMismatch(
                f"stage {stage.name!r} of method {method.name!r} in {stage_dir} was trained on stage {name!r} at step "
                f"{was}, which is now at step {step}; delete {stage_dir} to train it again on the new {name!r}"
            )


def _train_step(stage: Stage, micro_batches: int = 1):
    if stage.num_steps == 0:  # a computed stage: `fit` only checkpoints its parameters
        return lambda state, batch, key: (state, {})
    make = make_bn_train_step if stage.batch_norm else make_train_step
    return make(stage.loss, stage.optimizer, micro_batches=micro_batches)


# `curve(params) -> dict | None`: a learning-curve point for `{stage name: parameters}` of the stages so far.
Curve = Callable[[dict[str, Any]], "dict | None"]


def restore_untargeted(stage_dir: Path):
    """Returns a stage's parameters from its latest orbax checkpoint, restored without a target and checked against `stage.json`.

    No `stage.init` is needed for the structure, so nothing is computed: `jaxmotion.load` and the
    restore of computed stages (`Stage.num_steps == 0`, e.g. MotionMap's t-SNE codebook) use it.
    """
    _, restored = loop.restore_untargeted(Path(stage_dir) / "ckpt")  # onto this process's devices when saved on others
    params = jax.tree.map(jnp.asarray, restored["params"])
    manifest = Path(stage_dir) / MANIFEST
    want = json.loads(manifest.read_text()).get("params") if manifest.is_file() else None
    if want is not None and param_shapes(params) != want:
        raise CheckpointError(f"{stage_dir}: the checkpoint's parameters do not match the shapes its stage.json lists")
    return params


def _computed_from_checkpoint(method: Method, stage: Stage, stage_dir: Path, upstream: dict[str, int] | None):
    """Returns a computed stage's checkpointed parameters without computing them again, or None.

    None unless the stage computes its parameters (`num_steps == 0`) and `stage_dir` holds its
    checkpoint and `stage.json`. Training with `--resume` would restore that checkpoint over a fresh
    computation anyway; this skips the computation (MotionMap's t-SNE map takes minutes). The folder
    is checked as `check_stage_dir` does (method, stage, upstream steps), the shapes against its `stage.json`.
    """
    if stage.num_steps != 0 or not (stage_dir / MANIFEST).is_file() or not (stage_dir / "ckpt").is_dir():
        return None
    params = restore_untargeted(stage_dir)
    check_stage_dir(method, stage, TrainState(step=0, params=params, opt_state=None), stage_dir, upstream)
    return params


def run_stage(
    method: Method, stage: Stage, cfg, workdir: str | Path, trained: dict[str, Any], resume: bool = False,
    upstream: dict[str, int] | None = None, curve: Curve | None = None,
):
    """Returns the trained parameters of one stage in `workdir/<stage.name>` (its frozen inputs from `trained`).

    `upstream` maps the frozen stages to their step counts (default: their configured `num_steps`).
    `curve` is evaluated every `cfg.curve_every` steps with the earlier stages and this one's current
    parameters, into the stage's log (`loop.fit`). A computed stage already checkpointed is restored
    with `--resume`, not computed again (`_computed_from_checkpoint`).
    """
    stage_dir = Path(workdir) / stage.name
    upstream = {n: int(v) for n, v in (upstream or {}).items()}
    if resume:
        done = _computed_from_checkpoint(method, stage, stage_dir, upstream)
        if done is not None:
            return done
    state = init_state(stage, trained)
    check_stage_dir(method, stage, state, stage_dir, upstream)
    stage_dir.mkdir(parents=True, exist_ok=True)
    manifest = stage_dir / MANIFEST
    if not manifest.exists() and distributed.is_main():
        # Written whole or not at all: a kill mid-write must not leave a manifest that stops `--resume`.
        write_text_atomic(manifest, json.dumps(_manifest(method, stage, state, upstream), indent=1))
    micro_batches = getattr(cfg, "micro_batches", 1)
    state = fit(
        state, _train_step(stage, micro_batches), stage.batches or (lambda rng: None), num_steps=stage.num_steps, workdir=stage_dir,
        seed=stage.data_seed, resume=resume, ckpt_every=cfg.ckpt_every, log_every=cfg.log_every,
        desc=f"{method.name} {stage.name}",
        evaluate=None if curve is None else (lambda p: curve({**trained, stage.name: p})),
        eval_every=getattr(cfg, "curve_every", 0), micro_batches=micro_batches,
    )
    return state.params


def restore_stage(method: Method, stage: Stage, workdir: str | Path, trained: dict[str, Any]):
    """Returns one stage's parameters from the latest checkpoint in `workdir/<stage.name>`.

    A checkpoint that does not restore although `stage.json` says it fits is unreadable (truncated,
    half-written): a `CheckpointError` that points at `train --resume`, which falls back to the
    checkpoint before it. Without `stage.json` it is reported as a mismatch.
    """
    stage_dir = Path(workdir) / stage.name
    done = _computed_from_checkpoint(method, stage, stage_dir, None)
    if done is not None:
        return done
    state = init_state(stage, trained)
    check_stage_dir(method, stage, state, stage_dir)
    try:
        return restore_params(stage_dir, state).params
    except FileNotFoundError as e:
        raise FileNotFoundError(f"stage {stage.name!r} of method {method.name!r}: {e}") from e
    except Exception as e:  # orbax reports a structure mismatch as a long tree diff
        if (stage_dir / MANIFEST).exists():
            raise CheckpointError(
                f"stage {stage.name!r} of method {method.name!r}: {e}; its stage.json fits this config, so the "
                "checkpoint is unreadable: `jaxmotion train --resume` falls back to the one before it and trains on"
            ) from e
        raise CheckpointMismatch(
            f"stage {stage.name!r} of method {method.name!r}: the checkpoint in {stage_dir / 'ckpt'} does not "
            f"fit this config's parameters ({type(e).__name__}: {str(e).splitlines()[0][:300]})"
        ) from e


def train(method: Method, cfg, prep, workdir: str | Path, resume: bool = False, curve: Curve | None = None) -> dict[str, Any]:
    """Returns `{stage name: trained parameters}` after training every stage of `method` in order.

    With `resume`, stages already finished are restored and an interrupted one continues from its
    latest checkpoint (the same batches and keys as an uninterrupted run); without it, a stage
    folder that already holds checkpoints is an error (nothing is overwritten). `curve`: see `run_stage`.
    """
    trained: dict[str, Any] = {}
    steps: dict[str, int] = {}
    stages = method.stages(cfg, prep)
    mesh = distributed.data_mesh()
    for stage in stages:  # a batch that does not split over the devices is reported before any stage trains
        if stage.num_steps:
            distributed.check_batch(stage.batches(np.random.default_rng([stage.data_seed, 0])), mesh,
                                    f"stage {stage.name!r} of method {method.name!r}", getattr(cfg, "micro_batches", 1))
    for stage in stages:
        trained[stage.name] = run_stage(
            method, stage, cfg, workdir, trained, resume, {n: steps[n] for n in stage.frozen}, curve
        )
        steps[stage.name] = stage.num_steps
    return trained


def restore(method: Method, cfg, prep, workdir: str | Path) -> dict[str, Any]:
    """Returns `{stage name: parameters}` from the latest checkpoints `train` wrote in `workdir`."""
    trained: dict[str, Any] = {}
    for stage in method.stages(cfg, prep):
        trained[stage.name] = restore_stage(method, stage, workdir, trained)
    return trained
