"""Synthetic multimodal human motion with known modes: the library's built-in default dataset.

Real datasets only ever show one future per past, so a method's mode coverage can only be
estimated ([protocol §2][metrics], MM sets). Here the generating process is known, so every test window
comes with its full set of possible futures and their probabilities (`test_modes`).

Skeleton
    17 joints in Human3.6M order (the joints DLow keeps): Hips (root), right leg
    RHip-RKnee-RFoot, left leg LHip-LKnee-LFoot, Spine, Thorax, Neck, Head, left arm
    LShoulder-LElbow-LWrist, right arm RShoulder-RElbow-RWrist. Y up, the body faces +Z, the
    subject's left is +X, metres. The rest pose (all angles zero) stands upright with the arms
    hanging, ankles at y = 0.
    Bone lengths per subject: a global scale U(0.9, 1.1) times a per-bone jitter U(0.95, 1.05).
    The jitter is shared by the two sides of a left/right bone pair, so a mirrored subject
    (`LEFT_RIGHT_PAIRS`) has the same bone lengths as the original.

Motion
    Each joint has Euler angles (x = flexion, y = twist, z = ab/adduction, composed
    `Rz @ Ry @ Rx`) in its parent's frame, driven by parametric functions of time; numpy forward
    kinematics turns them into global positions `(T, 17, 3)`. The root never rotates, the
    facing direction is +Z throughout, and the root's horizontal position stays at the origin
    apart from the sway, so root-relative frames ([protocol §1][representation]) see all of the motion.

Segments and modes
    A sequence is a concatenation of segments of exactly `t_pred = 60` frames (2 s at 30 fps).
    Each segment's action is drawn i.i.d. from `MODE_NAMES` with the imbalanced probabilities
    `MODE_PROBS` (rarest 0.04). Every segment starts at the same neutral pose (rest pose plus
    zero sway) and returns to it, so segments chain with continuous positions.
    - Every action rides on the same lateral weight shift: the pelvis moves `sway * sin(2 pi u)`
      (u = frame / 60 within the segment, one cycle per segment) with the feet kept planted
      and the torso leaning against it. Because the sway is periodic, it joins segments with
      continuous velocity, and because it runs in every segment, the phase within the current
      segment can be read from any 15 observed frames.
    - On top of that, each action adds an action-specific pattern multiplied by an envelope
      that is 0 at the segment ends, rises with a half-cosine ramp over `RAMP_FRAMES = 15`
      frames (0.5 s), stays at 1, and falls over the last 15 frames. Envelope value and slope
      are 0 at both ends, so action switches are velocity-continuous as well. We use this
      plateau instead of `sin^2(pi u)` so that an action is clearly visible within 15 frames
      of its start: that is what separates the modes of a window whose decision point lies
      late in its future (distances below).
    - Per-subject style (deterministic per subject, drawn from the seed): `amplitude`
      U(0.85, 1.15) scales every action's angles, `sway` U(0.03, 0.05) m, `tempo`
      U(0.85, 1.15) scales the stepping and waving frequencies.
    - There is no per-segment noise: given the subject, the action and the frame within the
      segment, the pose is fixed. A window whose last observed frame is `e` therefore has a
      deterministic future up to the next segment boundary `b` (the smallest multiple of 60
      with `b >= e`; `b == e` when aligned), and from `b` on it follows one of the 6 actions.
      Frame `b` itself is the neutral pose for every action, so the 6 futures agree on the
      first `b - e + 1` frames and differ afterwards. With test windows starting every 15
      frames, `b - e` is 0, 15, 30 or 45.

Splits and seeds
    `make_synthetic(seed)` derives every random number from `seed` alone:
    subject `i` (0-based, train subjects first) uses `default_rng([seed, 0, i])` for its bone
    lengths and style; the train and test action draws use `default_rng([seed, 1])` and
    `default_rng([seed, 2])`. Defaults: train subjects S1-S5 x 8 sequences x 20 segments
    (40 sequences, 48 000 frames), test subjects S6-S7 x 4 sequences x 10 segments
    (8 sequences, 280 test windows). Sequences have `action = "mixed"`; their per-segment
    action indices are `dataset.info["train_segments"]` / `["test_segments"]` (one int array
    per sequence, same order as `dataset.train` / `dataset.test`; `frame_labels` expands them).

Distances between modes (seed 0, 280 test windows, 15 pairs of modes per window)
    ADE-term `(1/t_pred) sum_t ||a_t - b_t||` between two modes of the same window, metres:

    | frames before the decision point | windows | min   | median |
    | -------------------------------- | ------- | ----- | ------ |
    | 0 (aligned)                      | 64      | 0.365 | 1.00   |
    | 15                               | 72      | 0.291 | 0.82   |
    | 30                               | 72      | 0.182 | 0.50   |
    | 45                               | 72      | 0.058 | 0.16   |

    The closest pair is idle vs walk-in-place. FDE cannot tell the modes of an aligned
    window apart: its last future frame is the last frame of the new segment, where every
    action has returned to (almost exactly) the neutral pose.

MM threshold
    `MM_THRESHOLD = 0.015` m on the 48-vector of the last observed pose ([protocol §2][metrics]).
    Chosen so that MM ground truth is exact here: for seeds 0-5, the future of every member of
    a window's MM set is bitwise one of that window's 6 modes (tested), i.e. the MM futures are
    samples of the window's own modes. Above about 0.019 m this breaks (seed-dependent, up to
    0.024): a mid-segment idle pose then matches the near-neutral last pose of an aligned
    window, whose futures are different. Mean MM set size (including the window itself) at
    seed 0: 15.1 (11.6-15.1 for seeds 0-5; 2.5% of windows have only themselves); 25 at 0.1
    and 185 of 280 at 0.5, the threshold used for real datasets.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxmotion.data.types import MotionDataset, Sequence, Skeleton
from jaxmotion.data.windows import test_starts, to_frames

FPS = 30.0
T_HIS = 15
T_PRED = 60
SEGMENT_LEN = T_PRED
RAMP_FRAMES = 15
MM_THRESHOLD = 0.015

MODE_NAMES = ("idle", "walk_in_place", "wave_right_hand", "squat", "raise_both_arms", "kick_left_leg")
MODE_PROBS = (0.40, 0.25, 0.15, 0.10, 0.06, 0.04)

JOINT_NAMES = (
    "Hips", "RHip", "RKnee", "RFoot", "LHip", "LKnee", "LFoot", "Spine", "Thorax", "Neck",
    "Head", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist",
)  # fmt: skip
PARENTS = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)
SKELETON = Skeleton(names=JOINT_NAMES, parents=PARENTS)

# (left, right) joint indices; mirroring swaps each pair and negates x.
LEFT_RIGHT_PAIRS = ((4, 1), (5, 2), (6, 3), (11, 14), (12, 15), (13, 16))

# Offset of each joint from its parent in the rest pose, metres, for an average-sized subject
# (roughly Human3.6M's mean bone lengths).
_REST_OFFSETS = (
    (0.0, 0.0, 0.0),
    (-0.13, 0.0, 0.0), (0.0, -0.44, 0.0), (0.0, -0.44, 0.0),
    (0.13, 0.0, 0.0), (0.0, -0.44, 0.0), (0.0, -0.44, 0.0),
    (0.0, 0.23, 0.0), (0.0, 0.25, 0.0), (0.0, 0.11, 0.0), (0.0, 0.12, 0.0),
    (0.16, -0.03, 0.0), (0.0, -0.28, 0.0), (0.0, -0.25, 0.0),
    (-0.16, -0.03, 0.0), (0.0, -0.28, 0.0), (0.0, -0.25, 0.0),
)  # fmt: skip

HIPS, RHIP, RKNEE, RFOOT, LHIP, LKNEE, LFOOT, SPINE, THORAX, NECK, HEAD = range(11)
LSHOULDER, LELBOW, LWRIST, RSHOULDER, RELBOW, RWRIST = range(11, 17)
_X, _Y, _Z = 0, 1, 2


class SubjectParams(NamedTuple):
    """A synthetic subject: bone offsets `(17, 3)` in metres and its style factors."""

    name: str
    offsets: np.ndarray
    amplitude: float
    sway: float
    tempo: float


class TestModes(NamedTuple):
    """The known futures of every test window, in `test_windows` order.

    `modes` `(N, 6, t_pred, D)` float32 frame vectors (one per action in `MODE_NAMES` order),
    `probs` `(6,)`, `true_mode` `(N,)` the index of the mode the data actually took, and
    `boundary` `(N,)` the number of future frames before the decision point (0, 15, 30 or 45):
    all modes agree on future frames `[0, boundary]` and differ afterwards.
    """

    __test__ = False  # keep pytest from collecting this class

    modes: np.ndarray
    probs: np.ndarray
    true_mode: np.ndarray
    boundary: np.ndarray


def make_subject(name: str, rng: np.random.Generator) -> SubjectParams:
    """Returns a subject with random bone lengths and style (module docstring, Skeleton)."""
    rest = np.asarray(_REST_OFFSETS, dtype=np.float64)
    scale = rng.uniform(0.9, 1.1)
    jitter = rng.uniform(0.95, 1.05, size=len(PARENTS))
    for left, right in LEFT_RIGHT_PAIRS:
        jitter[right] = jitter[left]
    amplitude, sway, tempo = rng.uniform(0.85, 1.15), rng.uniform(0.03, 0.05), rng.uniform(0.85, 1.15)
    return SubjectParams(name, rest * (scale * jitter)[:, None], float(amplitude), float(sway), float(tempo))


def sample_actions(rng: np.random.Generator, n: int) -> np.ndarray:
    """Returns `(n,)` i.i.d. action indices drawn with probabilities `MODE_PROBS`."""
    return rng.choice(len(MODE_NAMES), size=n, p=np.asarray(MODE_PROBS)).astype(np.int64)


def envelope(u: np.ndarray) -> np.ndarray:
    """Returns the action envelope at segment phase `u = frame / SEGMENT_LEN` in [0, 1], of `u`'s shape.

    0 with zero slope at both ends, half-cosine ramps of `RAMP_FRAMES` frames, 1 in between.
    """
    r = RAMP_FRAMES / SEGMENT_LEN

    def ramp(x):
        return 0.5 - 0.5 * np.cos(np.pi * np.clip(x / r, 0.0, 1.0))

    return ramp(u) * ramp(1.0 - u)


def _segment_motion(subject: SubjectParams, action: int) -> tuple[np.ndarray, np.ndarray]:
    """Returns `(angles (L, 17, 3), root (L, 3))` of one segment of `action` for `subject`."""
    u = np.arange(SEGMENT_LEN) / SEGMENT_LEN
    env = envelope(u)
    a = subject.amplitude
    ang = np.zeros((SEGMENT_LEN, len(PARENTS), 3))
    thigh = np.linalg.norm(subject.offsets[RKNEE])
    shin = np.linalg.norm(subject.offsets[RFOOT])
    leg = thigh + shin
    root = np.zeros((SEGMENT_LEN, 3))
    root[:, 1] = leg

    # Weight shift shared by every action; the legs tilt so the ankles stay where they were.
    shift = subject.sway * np.sin(2 * np.pi * u)
    tilt = -np.arcsin(shift / leg)
    root[:, 0] += shift
    root[:, 1] -= leg * (1 - np.cos(tilt))
    ang[:, [RHIP, LHIP], _Z] += tilt[:, None]
    ang[:, SPINE, _Z] += 1.5 * shift
    ang[:, NECK, _Z] -= 1.5 * shift

    name = MODE_NAMES[action]
    if name == "idle":
        wobble = env * np.sin(2 * np.pi * u)
        ang[:, [LSHOULDER, RSHOULDER], _X] += 0.15 * a * wobble[:, None]
        ang[:, NECK, _Y] += 0.3 * a * wobble
    elif name == "walk_in_place":
        phase = 2 * np.pi * 2 * subject.tempo * u
        lift_l = env * np.maximum(np.sin(phase), 0.0) ** 2
        lift_r = env * np.maximum(-np.sin(phase), 0.0) ** 2
        for hip, knee, lift in ((LHIP, LKNEE, lift_l), (RHIP, RKNEE, lift_r)):
            ang[:, hip, _X] -= 1.1 * a * lift
            ang[:, knee, _X] += 1.8 * a * lift
        # Arms swing against the legs, elbows slightly bent.
        ang[:, LSHOULDER, _X] += 0.5 * a * env * np.sin(phase)
        ang[:, RSHOULDER, _X] -= 0.5 * a * env * np.sin(phase)
        ang[:, [LELBOW, RELBOW], _X] -= 0.5 * a * env[:, None]
    elif name == "wave_right_hand":
        waves = np.sin(2 * np.pi * 3 * subject.tempo * u)
        ang[:, RSHOULDER, _Z] -= 2.5 * a * env
        ang[:, RELBOW, _Z] += a * env * (0.6 * waves - 0.3)
        ang[:, NECK, _Y] -= 0.3 * a * env
    elif name == "squat":
        # Knee = 2 x hip flexion keeps the shin's tilt opposite the thigh's, so the ankle stays
        # under the hip and dropping the pelvis by leg * (1 - cos) keeps it on the ground.
        hip = 0.95 * a * env
        ang[:, [RHIP, LHIP], _X] -= hip[:, None]
        ang[:, [RKNEE, LKNEE], _X] += 2 * hip[:, None]
        root[:, 1] -= leg * (1 - np.cos(hip))
        ang[:, SPINE, _X] += 0.5 * a * env
        ang[:, [LSHOULDER, RSHOULDER], _X] -= 1.3 * a * env[:, None]
    elif name == "raise_both_arms":
        ang[:, [LSHOULDER, RSHOULDER], _X] -= 2.7 * a * env[:, None]
        ang[:, SPINE, _X] -= 0.15 * a * env
    elif name == "kick_left_leg":
        # The knee bends while the thigh rises, snaps straight at mid-segment, then bends back.
        snap = np.exp(-(((u - 0.5) / 0.12) ** 2))
        ang[:, LHIP, _X] -= a * env * (0.6 + 0.7 * snap)
        ang[:, LKNEE, _X] += 1.4 * a * env * (1 - snap)
        ang[:, LSHOULDER, _Z] += 0.8 * a * env
        ang[:, RSHOULDER, _Z] -= 0.8 * a * env
        ang[:, SPINE, _X] -= 0.2 * a * env
    else:  # pragma: no cover - MODE_NAMES and this table are edited together
        raise AssertionError(name)
    return ang, root


def _rotations(angles: np.ndarray) -> np.ndarray:
    """Returns `Rz @ Ry @ Rx` rotation matrices `(..., 3, 3)` from Euler angles `(..., 3)`."""
    c, s = np.cos(angles), np.sin(angles)
    one, zero = np.ones_like(c[..., 0]), np.zeros_like(c[..., 0])

    def mat(rows):
        return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)

    rx = mat([[one, zero, zero], [zero, c[..., 0], -s[..., 0]], [zero, s[..., 0], c[..., 0]]])
    ry = mat([[c[..., 1], zero, s[..., 1]], [zero, one, zero], [-s[..., 1], zero, c[..., 1]]])
    rz = mat([[c[..., 2], -s[..., 2], zero], [s[..., 2], c[..., 2], zero], [zero, zero, one]])
    return rz @ ry @ rx


def forward_kinematics(offsets: np.ndarray, angles: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Returns global joint positions `(T, J, 3)`.

    `offsets` `(J, 3)` rest offsets from each joint's parent, `angles` `(T, J, 3)` local Euler
    angles (a joint's rotation moves its children), `root` `(T, 3)` root positions. Parents must
    precede children (true for `PARENTS`).
    """
    local = _rotations(angles)
    glob = np.empty_like(local)
    pos = np.empty(angles.shape[:2] + (3,))
    glob[:, 0], pos[:, 0] = local[:, 0], root
    for j in range(1, len(PARENTS)):
        p = PARENTS[j]
        pos[:, j] = pos[:, p] + glob[:, p] @ offsets[j]
        glob[:, j] = glob[:, p] @ local[:, j]
    return pos


def segment_bank(subject: SubjectParams) -> np.ndarray:
    """Returns `(6, SEGMENT_LEN, 17, 3)` float32 positions of one segment of each action.

    A segment depends only on the subject and its action, so every sequence is a gather from
    this bank; rendering the modes from the same bank makes them bitwise equal to the data.
    """
    return np.stack(
        [forward_kinematics(subject.offsets, *_segment_motion(subject, k)) for k in range(len(MODE_NAMES))]
    ).astype(np.float32)


def frame_labels(segments: np.ndarray) -> np.ndarray:
    """Returns the per-frame action index `(len(segments) * SEGMENT_LEN,)` of a sequence."""
    return np.repeat(np.asarray(segments), SEGMENT_LEN)


def _subject_info(s: SubjectParams) -> dict:
    return {"offsets": s.offsets, "amplitude": s.amplitude, "sway": s.sway, "tempo": s.tempo}


def make_synthetic(
    seed: int = 0,
    *,
    num_train_subjects: int = 5,
    train_sequences: int = 8,
    train_segments: int = 20,
    num_test_subjects: int = 2,
    test_sequences: int = 4,
    test_segments: int = 10,
) -> MotionDataset:
    """Returns the synthetic multimodal dataset (module docstring: design, seeds, sizes).

    Subjects are named S1.. with train subjects first. `dataset.info` holds `mode_names`,
    `mode_probs`, `segment_len`, `seed`, `subjects` (name -> offsets and style), and
    `train_segments` / `test_segments` (per-sequence action indices), which is all `test_modes`
    needs.
    """
    counts = dict(num_train_subjects=num_train_subjects, train_sequences=train_sequences,
                  train_segments=train_segments, num_test_subjects=num_test_subjects,
                  test_sequences=test_sequences, test_segments=test_segments)  # fmt: skip
    for key, value in counts.items():
        if int(value) != value or value < 1:
            raise ValueError(f"make_synthetic: {key} must be a positive integer, got {value!r}")
    if test_segments * SEGMENT_LEN <= T_HIS + T_PRED:
        raise ValueError(
            f"make_synthetic: test_segments must be >= 2 to give test windows, got {test_segments}"
        )

    n_subjects = num_train_subjects + num_test_subjects
    subjects = [make_subject(f"S{i + 1}", np.random.default_rng([seed, 0, i])) for i in range(n_subjects)]

    def split(subs, n_seq, n_seg, rng):
        seqs, labels = [], []
        for sub in subs:
            bank = segment_bank(sub)
            for q in range(n_seq):
                actions = sample_actions(rng, n_seg)
                pos = bank[actions].reshape(-1, len(PARENTS), 3)
                seqs.append(Sequence(pos, FPS, sub.name, "mixed", f"{sub.name}/seq{q}"))
                labels.append(actions)
        return seqs, labels

    train, train_labels = split(
        subjects[:num_train_subjects], train_sequences, train_segments, np.random.default_rng([seed, 1])
    )
    test, test_labels = split(
        subjects[num_train_subjects:], test_sequences, test_segments, np.random.default_rng([seed, 2])
    )
    info = {
        "mode_names": MODE_NAMES,
        "mode_probs": np.asarray(MODE_PROBS),
        "segment_len": SEGMENT_LEN,
        "seed": seed,
        "subjects": {s.name: _subject_info(s) for s in subjects},
        "train_segments": train_labels,
        "test_segments": test_labels,
        "left_right_pairs": LEFT_RIGHT_PAIRS,
    }
    return MotionDataset("synthetic", SKELETON, FPS, T_HIS, T_PRED, MM_THRESHOLD, train, test, info, known_modes=test_modes)


def test_modes(dataset: MotionDataset) -> TestModes:
    """Returns every test window's known futures (`TestModes`), in `test_windows` order.

    Windows are those of `test_windows(sequence_frames(dataset.test), t_his, t_pred)`; mode `k`
    of a window is its observed past continued by the deterministic rest of the current segment
    and then a segment of action `k`, as root-relative root-dropped frame vectors (`to_frames`).
    """
    info = dataset.info
    missing = [k for k in ("subjects", "test_segments", "segment_len") if k not in info]
    if missing:
        raise ValueError(f"test_modes: dataset.info lacks {missing}; build the dataset with make_synthetic")
    if len(info["test_segments"]) != len(dataset.test):
        raise ValueError(
            f"test_modes: dataset.test has {len(dataset.test)} sequences but dataset.info['test_segments'] "
            f"has {len(info['test_segments'])}; do not edit dataset.test"
        )
    seg_len, t_his, t_pred = info["segment_len"], dataset.t_his, dataset.t_pred
    if t_pred != seg_len:
        raise ValueError(f"test_modes: t_pred ({t_pred}) must equal the segment length ({seg_len})")

    banks: dict[str, np.ndarray] = {}
    modes, true_mode, boundary = [], [], []
    for seq, segments in zip(dataset.test, info["test_segments"]):
        if seq.subject not in info["subjects"]:
            raise ValueError(
                f"test_modes: subject {seq.subject!r} of {seq.name!r} is not in dataset.info['subjects']"
            )
        if seq.positions.shape[0] != len(segments) * seg_len:
            raise ValueError(
                f"test_modes: {seq.name!r} has {seq.positions.shape[0]} frames but its "
                f"{len(segments)} segments need {len(segments) * seg_len}; do not edit dataset.test"
            )
        if seq.subject not in banks:
            p = info["subjects"][seq.subject]
            sub = SubjectParams(seq.subject, p["offsets"], p["amplitude"], p["sway"], p["tempo"])
            banks[seq.subject] = segment_bank(sub)
        bank = banks[seq.subject]
        frames = to_frames(seq.positions)
        for start in test_starts(seq.positions.shape[0], t_his + t_pred, t_his):
            end = start + t_his  # first future frame
            k = -(-end // seg_len)  # index of the segment that starts at the decision point
            # Two consecutive segments: the current one, then each alternative.
            strips = np.concatenate([np.broadcast_to(bank[segments[k - 1]], bank.shape), bank], axis=1)
            lo = end - (k - 1) * seg_len
            future = np.stack([to_frames(f) for f in strips[:, lo : lo + t_pred]])
            if not np.array_equal(future[segments[k]], frames[end : end + t_pred]):
                raise ValueError(
                    f"test_modes: {seq.name!r} does not match dataset.info; do not edit dataset.test"
                )
            modes.append(future)
            true_mode.append(segments[k])
            boundary.append(k * seg_len - end)
    return TestModes(
        np.stack(modes).astype(np.float32),
        np.asarray(MODE_PROBS, dtype=np.float32),
        np.asarray(true_mode, dtype=np.int64),
        np.asarray(boundary, dtype=np.int64),
    )


test_modes.__test__ = False  # keep pytest from collecting this function where it is imported
