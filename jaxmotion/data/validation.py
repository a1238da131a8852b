"""The validation split: training sequences held back to choose settings on, so the test split is never used for it.

`validation_split(ds)` returns a dataset whose `train` keeps four in five of the training
sequences and whose `test` is the fifth, taken evenly from every action (sorted by action, then
name, every `every`-th). Evaluation then runs the protocol on the held-back windows exactly as on
the test windows (test stride `t_his`, the multimodal ground truth among those windows). The test
sequences are dropped: nothing about them reaches a validation run. A config selects it with
`Config.split = "val"`; `info["validation"]` lists the held-back sequences.

The synthetic data's per-sequence labels (`info["train_segments"]`) follow their sequences, so its
known modes and action labels stay right on the held-back sequences.
"""

from __future__ import annotations

import dataclasses

from jaxmotion.data.types import MotionDataset

VALIDATION_EVERY = 5  # one training sequence in five, per action


def validation_indices(actions: list[str], names: list[str], every: int = VALIDATION_EVERY) -> list[int]:
    """Returns the indices of the held-back sequences: within each action, sorted by name, every `every`-th from the first."""
    if every < 2:
        raise ValueError(f"validation_indices: `every` must be >= 2 (something must stay for training), got {every}")
    held = []
    for action in sorted(set(actions)):
        group = sorted((n, i) for i, (a, n) in enumerate(zip(actions, names)) if a == action)
        held += [i for _, i in group[::every]]
    return sorted(held)


def validation_split(ds: MotionDataset, every: int = VALIDATION_EVERY) -> MotionDataset:
    """Returns `ds` with every `every`-th training sequence of each action as its test split and the rest as train."""
    seqs = ds.train
    held = set(validation_indices([s.action for s in seqs], [s.name for s in seqs], every))
    if not held or len(held) == len(seqs):
        raise ValueError(
            f"{ds.name}: a validation split needs at least two training sequences per split; "
            f"{len(seqs)} training sequences give {len(held)} held back"
        )
    keep = [i for i in range(len(seqs)) if i not in held]
    val = sorted(held)
    info = dict(ds.info, validation={"every": every, "held_back": [seqs[i].name for i in val]})
    if "train_segments" in info:
        segments = info["train_segments"]
        info["train_segments"] = [segments[i] for i in keep]
        info["test_segments"] = [segments[i] for i in val]
    return dataclasses.replace(ds, train=[seqs[i] for i in keep], test=[seqs[i] for i in val], info=info)
