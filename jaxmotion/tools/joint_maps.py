"""Which joint of a file is which joint of a model: by name, by a user's map, or by a built-in convention.

    mapping = match_skeleton(model_names, model_parents, file_names, file_parents, joint_map=None)
    # {model joint: file joint}; every model joint mapped, the file's hierarchy checked

Built-in conventions name the 21 joints of a humanoid body by role (`ROLES`: pelvis, spine, chest,
neck, head; per side clavicle, upper arm, forearm, hand, thigh, shin, foot, toe):
`bandai` (Bandai-Namco-2), `cmu` (the cgspeed BVH conversion of CMU), `mixamo`, `lafan1` (Ubisoft
LaFAN1) and `smpl22` (the SMPL body joints 0-21). A skeleton fits a convention when it has all 21
of its names (Mixamo's `mixamorig:` prefix, or any `namespace:` prefix, is ignored). Where both a
model and a file fit a convention, model joint -> role -> file joint.

The mapped file joints must form the model's tree: the nearest mapped ancestor of every model
joint's file joint must be its model parent's file joint (joints in between, like CMU's
`LHipJoint` or `Neck1`, are allowed). Otherwise `DataError` names the joint and both parents.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from jaxmotion.errors import DataError

_SIDED_ROLES = ("clavicle", "upperarm", "forearm", "hand", "thigh", "shin", "foot", "toe")
ROLES = ("pelvis", "spine", "chest", "neck", "head") + tuple(f"{s}_{r}" for s in "lr" for r in _SIDED_ROLES)


def _convention(central: tuple[str, ...], left: tuple[str, ...], right: tuple[str, ...]) -> dict[str, str]:
    return dict(zip(ROLES, central + left + right))


def _lr(names: tuple[str, ...], left: str, right: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    return tuple(n.format(side=left) for n in names), tuple(n.format(side=right) for n in names)


_BANDAI = _lr(("Shoulder_{side}", "UpperArm_{side}", "LowerArm_{side}", "Hand_{side}", "UpperLeg_{side}",
               "LowerLeg_{side}", "Foot_{side}", "Toes_{side}"), "L", "R")  # fmt: skip
_CMU = _lr(("{side}Shoulder", "{side}Arm", "{side}ForeArm", "{side}Hand", "{side}UpLeg", "{side}Leg", "{side}Foot",
            "{side}ToeBase"), "Left", "Right")  # fmt: skip
_LAFAN = _lr(("{side}Shoulder", "{side}Arm", "{side}ForeArm", "{side}Hand", "{side}UpLeg", "{side}Leg", "{side}Foot",
              "{side}Toe"), "Left", "Right")  # fmt: skip
_SMPL = _lr(("{side}_collar", "{side}_shoulder", "{side}_elbow", "{side}_wrist", "{side}_hip", "{side}_knee",
             "{side}_ankle", "{side}_foot"), "left", "right")  # fmt: skip

# Convention -> {role: joint name}. The chest is the joint the clavicles hang from.
CONVENTIONS: dict[str, dict[str, str]] = {
    "bandai": _convention(("Hips", "Spine", "Chest", "Neck", "Head"), *_BANDAI),
    "cmu": _convention(("Hips", "Spine", "Spine1", "Neck", "Head"), *_CMU),
    "mixamo": _convention(("Hips", "Spine", "Spine2", "Neck", "Head"), *_CMU),
    "lafan1": _convention(("Hips", "Spine", "Spine2", "Neck", "Head"), *_LAFAN),
    "smpl22": _convention(("pelvis", "spine1", "spine3", "neck", "head"), *_SMPL),
}
# Names a skeleton must also have to be read in a convention: they tell CMU from Mixamo, whose role names CMU shares.
_SIGNATURE = {"cmu": ("LowerBack",), "mixamo": ("Spine2",), "lafan1": ("Spine2",), "smpl22": ("spine2",)}


def plain_name(name: str) -> str:
    """Returns a joint name without a namespace prefix (`mixamorig:Hips`, `mixamorig1:Hips`, `Armature|Hips` -> `Hips`)."""
    return re.split(r"[:|]", name)[-1]


def conventions_of(names) -> list[str]:
    """Returns the built-in conventions whose every joint name (and signature name) is among `names`, in `CONVENTIONS` order."""
    have = {plain_name(n) for n in names}
    return [c for c, m in CONVENTIONS.items() if set(m.values()) <= have and set(_SIGNATURE.get(c, ())) <= have]


def read_joint_map(path: str | os.PathLike) -> dict[str, str]:
    """Returns `{model joint: file joint}` from a JSON object file (`--joint-map`)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: joint map not found")
    try:
        m = json.loads(path.read_text(encoding="utf-8-sig"))
    except json.JSONDecodeError as e:
        raise DataError(path, f"joint map is not JSON ({e})") from None
    if not isinstance(m, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in m.items()):
        raise DataError(path, 'joint map must be a JSON object {"model joint": "file joint", ...}')
    return m


def match_skeleton(
    model_names, model_parents, file_names, file_parents, joint_map: dict[str, str] | None = None, where: str | os.PathLike = "",
) -> tuple[dict[str, str], str]:
    """Returns `({model joint: file joint}, how)` for every model joint, the file's hierarchy checked (module docstring).

    Tried in order: `joint_map` (model joints it leaves out are matched by name), the same names,
    a built-in convention that both skeletons fit. `where` names the file in errors; `file_parents`
    None (joint positions without a tree) skips the hierarchy check.
    """
    model_names, file_names = list(model_names), list(file_names)
    plain = {plain_name(n): n for n in file_names}
    mapping = None
    if joint_map is not None:
        mapping = {m: joint_map.get(m, m) for m in model_names}
        bad = {m: f for m, f in mapping.items() if f not in file_names and f not in plain}
        if bad:
            raise DataError(where, f"joint map: file joints {sorted(set(bad.values()))} (for model joints {sorted(bad)}) "
                                   f"are not in the file (its joints: {file_names})")
        unknown = sorted(set(joint_map) - set(model_names))
        if unknown:
            raise DataError(where, f"joint map: {unknown} are not model joints (the model's: {model_names})")
        mapping = {m: f if f in file_names else plain[f] for m, f in mapping.items()}
        how = "joints: by the given joint map"
    elif all(plain_name(m) in plain for m in model_names):
        mapping = {m: plain[plain_name(m)] for m in model_names}
        how = "joints: matched by name"
    else:
        model_conv, file_conv = conventions_of(model_names), conventions_of(file_names)
        pairs = [(c, c) for c in model_conv if c in file_conv] or [(m, f) for m in model_conv for f in file_conv]
        if not pairs or len(set(plain_name(m) for m in model_names)) != len(model_names):
            missing = [m for m in model_names if plain_name(m) not in plain]
            raise DataError(where, _no_match(model_names, file_names, missing, model_conv, file_conv))
        pair = pairs[0]
        role_of = {name: role for role, name in CONVENTIONS[pair[0]].items()}
        if not all(plain_name(m) in role_of for m in model_names):
            extra = [m for m in model_names if plain_name(m) not in role_of]
            raise DataError(where, f"the model's joints {extra} have no role in the {pair[0]} convention; pass --joint-map FILE")
        mapping = {m: plain[CONVENTIONS[pair[1]][role_of[plain_name(m)]]] for m in model_names}
        how = f"joints: the model's {pair[0]} names mapped onto the file's {pair[1]} names (built-in joint map)"
    if file_parents is not None:
        check_hierarchy(model_names, model_parents, file_names, file_parents, mapping, where)
    return mapping, how


def _no_match(model_names, file_names, missing, model_conv, file_conv) -> str:
    fits = f"the file's names fit the built-in map(s) {file_conv}" if file_conv else "the file's names fit no built-in map"
    model = f"the model's fit {model_conv}" if model_conv else "the model's fit none"
    extra = [f for f in file_names if plain_name(f) not in {plain_name(m) for m in model_names}]
    return (
        f"skeleton does not match the model's: missing joints {missing}; extra joints {extra}; {fits} and {model} "
        f"(built-in: {', '.join(CONVENTIONS)}). Pass --joint-map FILE, a JSON object "
        f'{{"model joint": "file joint"}} (the model\'s {len(model_names)} joints: {model_names})'
    )


def check_hierarchy(model_names, model_parents, file_names, file_parents, mapping: dict[str, str], where: str | os.PathLike = "") -> None:
    """Raises `DataError` naming a model joint whose mapped file joint hangs from another joint than its model parent's."""
    file_index = {n: i for i, n in enumerate(file_names)}
    image = {mapping[m]: m for m in model_names}
    if len(image) != len(model_names):
        dup = sorted({f for f in mapping.values() if list(mapping.values()).count(f) > 1})
        raise DataError(where, f"joint map sends several model joints to the same file joint(s) {dup}")
    for j, m in enumerate(model_names):
        p = model_parents[j]
        a = file_parents[file_index[mapping[m]]]
        while a >= 0 and file_names[a] not in image:
            a = file_parents[a]
        got = image[file_names[a]] if a >= 0 else None
        want = model_names[p] if p >= 0 else None
        if got != want:
            fp = file_parents[file_index[mapping[m]]]
            raise DataError(
                where, f"hierarchy differs from the model's: model joint {m!r} hangs from {want or 'nothing (the root)'!r} "
                f"(file joint {mapping[want] if want else 'none'!r}), but its file joint {mapping[m]!r} hangs from "
                f"{file_names[fp] if fp >= 0 else 'nothing (the root)'!r}"
                + (f" (nearest mapped ancestor: model joint {got!r})" if got is not None and file_names[fp] != mapping[got] else "")
                + "; fix the file's hierarchy or map the joints with --joint-map FILE"
            )
