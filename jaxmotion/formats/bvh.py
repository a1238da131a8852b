"""BVH motion capture files: a parser and vectorised forward kinematics (numpy).

A BVH file has a HIERARCHY (joints with an OFFSET from their parent and a list of CHANNELS) and a
MOTION block (one row of channel values per frame). Rotation channels are Euler angles in degrees,
composed in the order they are written: channels `Zrotation Xrotation Yrotation` mean the local
rotation is `Rz @ Rx @ Ry`. Position channels, on any joint, replace that joint's offset.

    bvh = read_bvh("01_01.bvh")
    positions = forward_kinematics(bvh)          # (F, J, 3), in the file's units
    positions *= guess_scale(bvh)                # metres (CMU's cgspeed units are recognised)

`is_ground_node(bvh)` tells whether the root is a constant ground node (Bandai's `joint_Root`),
which body models drop; `is_ground_skeleton(bvh)` decides it from the skeleton alone, once for a
folder of clips (`data.datasets.load_bvh_folder`). Only numpy: this module sits below `body/` and `data/`.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from jaxmotion.errors import DataError

_POSITION_AXES = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
_ROTATION_AXES = {"Xrotation": 0, "Yrotation": 1, "Zrotation": 2}

# Input limits, each a named error: a body has tens of joints (a few hundred with fingers and face), and
# capture runs between 1 frame a minute and 100 kHz; beyond them a file is corrupt or a resource bomb.
MAX_JOINTS = 1000
FRAME_TIME_RANGE = (1e-5, 60.0)  # seconds

# Skeletons whose units cannot be guessed from their size (see `guess_scale`).
CMU_SCALE = 0.056444
_KNOWN_SCALES = {frozenset({"Hips", "LHipJoint", "RHipJoint", "LowerBack"}): CMU_SCALE}


@dataclasses.dataclass
class Bvh:
    """A parsed BVH file. End Sites are not joints here: they carry no channels.

    `offsets` is `(J, 3)` in file units, `channels[j]` the channel names of joint `j` in file order,
    and `motion` the `(F, C)` channel values with `C = sum(len(c) for c in channels)`; joint `j`'s
    values are the columns `channel_starts[j] : channel_starts[j] + len(channels[j])`.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    motion: np.ndarray
    frame_time: float
    path: str = ""

    @property
    def fps(self) -> float:
        """Returns the frame rate, `1 / frame_time`."""
        return 1.0 / self.frame_time

    @property
    def num_frames(self) -> int:
        return self.motion.shape[0]

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def channel_starts(self) -> tuple[int, ...]:
        """Returns the first motion column of each joint."""
        starts = np.cumsum([0] + [len(c) for c in self.channels])[:-1]
        return tuple(int(s) for s in starts)


def read_bvh(path: str | os.PathLike) -> Bvh:
    """Returns the parsed BVH file at `path`.

    Raises FileNotFoundError if it does not exist and `jaxmotion.errors.DataError` (a ValueError)
    naming the file if it is malformed: no HIERARCHY or MOTION, unknown channels, fewer motion rows
    than `Frames:` says, a row with the wrong number of values, non-numeric values, NaN or inf (with
    the frame and channel).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: BVH file not found")
    text = path.read_text(encoding="utf-8", errors="replace").removeprefix("\ufeff")  # a byte-order mark some editors write
    lines = text.splitlines()
    stripped = [line.strip() for line in lines]
    try:
        h0 = stripped.index("HIERARCHY")
    except ValueError:
        raise DataError(path, "no HIERARCHY section; not a BVH file") from None
    try:
        m0 = stripped.index("MOTION", h0)
    except ValueError:
        raise DataError(path, "no MOTION section (file truncated?)") from None

    names, parents, offsets, channels = _parse_hierarchy(path, stripped[h0 + 1 : m0])
    channel_names = [f"{n}:{c}" for n, chans in zip(names, channels) for c in chans]
    num_frames, frame_time, rows = _parse_motion_header(path, stripped, m0)
    motion = _parse_motion_rows(path, lines[rows:], num_frames, channel_names)
    return Bvh(
        names=tuple(names),
        parents=tuple(parents),
        offsets=np.asarray(offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(tuple(c) for c in channels),
        motion=motion,
        frame_time=frame_time,
        path=str(path),
    )


def _parse_hierarchy(path: Path, lines: list[str]):
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[list[str]] = []
    # Each open brace pushes the joint it belongs to; End Sites push None so their OFFSET is skipped.
    stack: list[int | None] = []
    expecting_brace = False
    pending: int | None = None
    seen: dict[str, int] = {}  # joint name -> HIERARCHY line
    for n, line in enumerate(lines):
        if not line:
            continue
        tokens = line.split()
        key = tokens[0]
        where = f"HIERARCHY line {n + 1} ({line!r})"
        if key in ("ROOT", "JOINT"):
            if len(tokens) < 2:
                raise DataError(path, f"{where}: joint without a name")
            if key == "JOINT" and not stack:
                raise DataError(path, f"{where}: JOINT outside of any ROOT")
            parent = -1 if key == "ROOT" else stack[-1]
            if parent is None:
                raise DataError(path, f"{where}: JOINT inside an End Site")
            name = " ".join(tokens[1:])
            if name in seen:  # joints are looked up by name: a second one would silently win or lose
                raise DataError(path, f"{where}: joint name {name!r} used twice (first at HIERARCHY line {seen[name]})")
            seen[name] = n + 1
            if len(names) == MAX_JOINTS:
                raise DataError(path, f"{where}: more than {MAX_JOINTS} joints (MAX_JOINTS); not a body skeleton")
            names.append(name)
            parents.append(parent)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            pending, expecting_brace = len(names) - 1, True
        elif key == "End":
            pending, expecting_brace = None, True
        elif key == "{":
            if not expecting_brace:
                raise DataError(path, f"{where}: '{{' without a joint")
            stack.append(pending)
            expecting_brace = False
        elif key == "}":
            if not stack:
                raise DataError(path, f"{where}: unbalanced '}}'")
            stack.pop()
        elif key == "OFFSET":
            if not stack:
                raise DataError(path, f"{where}: OFFSET outside of a joint")
            if stack[-1] is None:
                continue
            try:
                values = [float(v) for v in tokens[1:]]
            except ValueError:
                raise DataError(path, f"{where}: non-numeric OFFSET") from None
            if len(values) != 3 or not np.all(np.isfinite(values)):
                raise DataError(path, f"{where}: OFFSET needs 3 finite numbers")
            offsets[stack[-1]] = values
        elif key == "CHANNELS":
            if not stack or stack[-1] is None:
                raise DataError(path, f"{where}: CHANNELS outside of a joint")
            try:
                count = int(tokens[1])
            except (IndexError, ValueError):
                raise DataError(path, f"{where}: CHANNELS needs a count") from None
            chans = tokens[2:]
            if len(chans) != count:
                raise DataError(path, f"{where}: CHANNELS says {count} but lists {len(chans)}")
            unknown = [c for c in chans if c not in _POSITION_AXES and c not in _ROTATION_AXES]
            if unknown:
                raise DataError(path, f"{where}: unknown channels {unknown}")
            channels[stack[-1]] = chans
        else:
            raise DataError(path, f"{where}: unexpected keyword {key!r}")
    if stack:
        raise DataError(path, f"HIERARCHY has {len(stack)} unclosed '{{'")
    if not names:
        raise DataError(path, "HIERARCHY defines no joints")
    if parents.count(-1) != 1:
        raise DataError(path, f"expected exactly one ROOT, found {parents.count(-1)}")
    return names, parents, offsets, channels


def _parse_motion_header(path: Path, stripped: list[str], m0: int) -> tuple[int, float, int]:
    """Returns `(num_frames, frame_time, index of the first motion row)`."""
    header = [(i, s) for i, s in enumerate(stripped[m0 + 1 :], start=m0 + 1) if s][:2]
    if len(header) < 2:
        raise DataError(path, "MOTION lacks 'Frames:' and 'Frame Time:' lines (file truncated?)")
    (_, frames_line), (ft_index, ft_line) = header
    try:
        if not frames_line.startswith("Frames:"):
            raise ValueError
        num_frames = int(frames_line.split(":", 1)[1])
    except ValueError:
        raise DataError(path, f"expected 'Frames: N' after MOTION, got {frames_line!r}") from None
    try:
        if not ft_line.startswith("Frame Time:"):
            raise ValueError
        frame_time = float(ft_line.split(":", 1)[1])
    except ValueError:
        raise DataError(path, f"expected 'Frame Time: dt' after 'Frames:', got {ft_line!r}") from None
    if num_frames < 0:
        raise DataError(path, f"negative frame count {num_frames}")
    lo, hi = FRAME_TIME_RANGE
    if not (lo <= frame_time <= hi):
        raise DataError(path, f"Frame Time must be a positive number of seconds ({lo:g} to {hi:g}: 100 kHz to 1 frame a minute), got {frame_time}")
    return num_frames, frame_time, ft_index + 1


def _parse_motion_rows(path: Path, lines: list[str], num_frames: int, channel_names: list[str]) -> np.ndarray:
    num_channels = len(channel_names)
    rows = [line.split() for line in lines]
    rows = [r for r in rows if r]
    if len(rows) < num_frames:
        raise DataError(path, f"'Frames: {num_frames}' but only {len(rows)} motion rows (file truncated?)")
    if len(rows) > num_frames:
        raise DataError(path, f"'Frames: {num_frames}' but {len(rows)} motion rows")
    bad = [i for i, r in enumerate(rows) if len(r) != num_channels]
    if bad:
        raise DataError(
            path, f"motion row {bad[0]} has {len(rows[bad[0]])} values, expected {num_channels} "
            f"(HIERARCHY channels); {len(bad)} bad rows (file truncated?)"
        )
    if num_frames == 0:
        return np.zeros((0, num_channels))
    try:
        motion = np.array(rows, dtype=np.float64)
    except ValueError as e:
        for i, r in enumerate(rows):
            for v in r:
                try:
                    float(v)
                except ValueError:
                    raise DataError(path, f"non-numeric value {v!r} at frame {i} (motion row {i})") from None
        raise DataError(path, f"motion values are not numbers ({e})") from None
    if not np.all(np.isfinite(motion)):
        i, c = (int(v) for v in np.argwhere(~np.isfinite(motion))[0])
        raise DataError(path, f"non-finite value {motion[i, c]} at frame {i} (motion row {i}), channel {channel_names[c]}")
    return motion


def euler_matrices(angles_deg: np.ndarray, axes: str) -> np.ndarray:
    """Returns `(..., 3, 3)` rotation matrices `R_a0 @ R_a1 @ ...` for Euler angles in degrees.

    `angles_deg` is `(..., len(axes))`; `axes` names the axis of each angle, e.g. `"ZXY"`. This is
    the BVH convention: rotations composed in channel order (intrinsic rotations).
    """
    angles = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for k, axis in enumerate(axes.upper()):
        c, s = np.cos(angles[..., k]), np.sin(angles[..., k])
        r = np.zeros(angles.shape[:-1] + (3, 3))
        i = "XYZ".index(axis)
        j, l = (i + 1) % 3, (i + 2) % 3
        r[..., i, i] = 1.0
        r[..., j, j] = c
        r[..., l, l] = c
        r[..., j, l] = -s
        r[..., l, j] = s
        out = out @ r
    return out


def forward_kinematics(bvh: Bvh, frames: np.ndarray | slice | list[int] | None = None) -> np.ndarray:
    """Returns `(F, J, 3)` global joint positions in the file's units.

    `frames` selects motion rows (an index array or list, or a slice; all frames if None). Each joint's
    transform is `global_j = global_parent @ [R_j | t_j]` with `t_j` its position channels (or
    its OFFSET when it has none) and `R_j` its rotation channels composed in file order.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    motion = np.atleast_2d(motion)
    num_frames = motion.shape[0]
    rotations = np.empty((bvh.num_joints, num_frames, 3, 3))
    positions = np.empty((num_frames, bvh.num_joints, 3))
    for j, (parent, chans, start) in enumerate(zip(bvh.parents, bvh.channels, bvh.channel_starts)):
        if parent >= j:
            raise DataError(bvh.path, f"joint {j} listed before its parent {parent}")
        local_t = np.broadcast_to(bvh.offsets[j], (num_frames, 3)).copy()
        rot_cols, rot_axes = [], ""
        for k, name in enumerate(chans):
            if name in _POSITION_AXES:
                local_t[:, _POSITION_AXES[name]] = motion[:, start + k]
            else:
                rot_cols.append(start + k)
                rot_axes += name[0]
        local_r = euler_matrices(motion[:, rot_cols], rot_axes)
        if parent < 0:
            rotations[j] = local_r
            positions[:, j] = local_t
        else:
            rotations[j] = rotations[parent] @ local_r
            positions[:, j] = positions[:, parent] + np.einsum("fik,fk->fi", rotations[parent], local_t)
    return positions


def guess_scale(bvh: Bvh) -> float:
    """Returns metres per file unit: a known skeleton's, else a power of ten from the body size.

    The size is the largest distance between two body joints in the rest pose (offsets only); a human
    measures 1-2.5 m, so a size in [0.5, 5) means metres, [50, 500) centimetres, [500, 5000)
    millimetres. Anything else (e.g. inches) needs an explicit scale.
    """
    names = set(bvh.names)
    for known, s in _KNOWN_SCALES.items():
        if known <= names:
            return s
    rest = np.zeros((bvh.num_joints, 3))
    for j, p in enumerate(bvh.parents):
        rest[j] = bvh.offsets[j] + (rest[p] if p >= 0 else 0.0)
    if is_ground_node(bvh):
        rest = rest[1:]  # the body's offset from a ground node says nothing about its size
    with np.errstate(over="ignore", invalid="ignore"):  # huge offsets: an inf size, reported below
        size = float(np.max(np.linalg.norm(rest[:, None] - rest[None], axis=-1)))
    for lo, s in ((0.5, 1.0), (50.0, 0.01), (500.0, 0.001)):
        if lo <= size < 10 * lo:
            return s
    raise DataError(bvh.path, f"cannot guess units from a rest-pose size of {size:.3g}; pass scale=")


def is_ground_skeleton(bvh: Bvh) -> bool:
    """Returns whether the skeleton's root is a ground node, judged by the skeleton alone (not the motion).

    A ground node has a zero offset and exactly one child that carries the body: the child has
    position channels of its own, or a zero offset (so the root adds no point of its own). Bandai's
    `joint_Root` is one; CMU's `Hips` (three children) is not. Decide it once for a folder of clips
    from one exporter: `is_ground_node` also asks for constant channels, which a clip in which the
    ground node carries the walk does not have.
    """
    children = [j for j, p in enumerate(bvh.parents) if p == 0]
    if len(children) != 1 or np.any(bvh.offsets[0] != 0):
        return False
    c = children[0]
    return any(ch in _POSITION_AXES for ch in bvh.channels[c]) or bool(np.all(bvh.offsets[c] == 0))


def is_ground_node(bvh: Bvh) -> bool:
    """Returns whether the root is a ground node: zero offset, one child, constant channels."""
    one_child = sum(p == 0 for p in bvh.parents) == 1
    root_values = bvh.motion[:, : len(bvh.channels[0])]
    still = root_values.size == 0 or bool(np.all(root_values == root_values[:1]))
    return one_child and bool(np.all(bvh.offsets[0] == 0)) and still
