"""Marker sets defined by name and attachment, for any skeleton whose joints can be named by role.

A marker is attached rigidly to the bone driven by joint `role` (its rotation moves the marker).
Its position is given once, in a standing reference pose, in a body frame (forward, left, up):
the point `along` of the way from joint `role` to joint `to` (0 = at `role`), moved by
`(fwd, lat, up)` metres. Left-side markers are written once; `R...` markers mirror `lat`.
The numbers are anatomical guesses for an adult (skin markers sit 2-12 cm off the bone); a
calibration (`fit.calibrate`) refines offsets and bone lengths for a real subject.

Sets: `cmu41` (the CMU / MOJO "CMU 41" layout: C7 CLAV STRN T10 RBAK and 18 per side), `vicon53`
(the 53 labels of `../shared/data/vicon-c3d`), `ssm2_67` (SSM2-style 67: vicon53 + 14), and
`bandai` (cmu41 on the 21-joint Bandai-Namco-2 skeleton, which has no fingers or head top:
those markers hang off the hand and head joints). The `bandai` set also attaches the elbow, wrist,
knee and ankle markers to the bone they sit on anatomically (ELB on the humerus, WRA/WRB on the
forearm, KNE on the femur, ANK on the shank; `SET_OVERRIDES`), at the same reference positions, so
every limb bone carries two rigid markers (`LIMB_MARKER_PAIRS`) and bone deformation is measurable
from markers alone. The other sets keep the generic attachments their C3D fits were made with.
"""

from __future__ import annotations

from typing import NamedTuple


class MarkerSpec(NamedTuple):
    """Where a marker sits on the body: on bone `role` (towards joint `to`, `along` its length) and offset `fwd`, `lat`, `up` metres."""

    role: str
    to: str | None
    along: float
    fwd: float
    lat: float
    up: float


# Role -> joint names tried in order (Bandai-Namco-2, CMU cgspeed, SMPL, Mixamo-like).
ROLE_ALIASES = {
    "pelvis": ("Hips", "pelvis", "Pelvis", "hip"),
    "spine": ("Spine", "LowerBack", "spine1", "Spine1"),
    "chest": ("Chest", "Spine1", "spine3", "Spine2", "chest"),
    "neck": ("Neck", "Neck1", "neck"),
    "head": ("Head", "head"),
    "l_clavicle": ("Shoulder_L", "LeftShoulder", "left_collar", "LeftCollar"),
    "l_upperarm": ("UpperArm_L", "LeftArm", "left_shoulder", "LeftUpArm"),
    "l_forearm": ("LowerArm_L", "LeftForeArm", "left_elbow", "LeftLowArm"),
    "l_hand": ("Hand_L", "LeftHand", "left_wrist"),
    "l_thigh": ("UpperLeg_L", "LeftUpLeg", "left_hip"),
    "l_shin": ("LowerLeg_L", "LeftLeg", "left_knee", "LeftLowLeg"),
    "l_foot": ("Foot_L", "LeftFoot", "left_ankle"),
    "l_toe": ("Toes_L", "LeftToeBase", "left_foot", "LeftToe"),
}
for _k, _v in list(ROLE_ALIASES.items()):
    if _k.startswith("l_"):
        ROLE_ALIASES["r_" + _k[2:]] = tuple(
            n.replace("_L", "_R").replace("Left", "Right").replace("left", "right") for n in _v
        )

_S = MarkerSpec
# Central markers (lat > 0 is the body's left).
_CENTRAL = {
    "ARIEL": _S("head", None, 0.0, 0.0, 0.0, 0.19),
    "C7": _S("chest", "neck", 1.0, -0.06, 0.0, 0.0),
    "CLAV": _S("chest", "neck", 1.0, 0.07, 0.0, -0.04),
    "STRN": _S("chest", "neck", 0.3, 0.11, 0.0, 0.0),
    "T10": _S("spine", "chest", 0.8, -0.11, 0.0, 0.0),
    "RBAK": _S("chest", "neck", 0.5, -0.10, -0.08, 0.0),
    "LBAK": _S("chest", "neck", 0.5, -0.10, 0.08, 0.0),
}
# Left-side markers, by suffix ("FHD" -> LFHD and RFHD).
_SIDED = {
    "FHD": _S("head", None, 0.0, 0.09, 0.06, 0.11),
    "BHD": _S("head", None, 0.0, -0.09, 0.06, 0.09),
    "SHO": _S("clavicle", "upperarm", 1.0, 0.0, 0.0, 0.04),
    "FSH": _S("clavicle", "upperarm", 1.0, 0.05, 0.0, 0.01),
    "BSH": _S("clavicle", "upperarm", 1.0, -0.06, 0.0, 0.01),
    "UPA": _S("upperarm", "forearm", 0.5, 0.0, 0.05, 0.0),
    "ELB": _S("forearm", None, 0.0, -0.02, 0.04, 0.0),
    "IEL": _S("forearm", None, 0.0, 0.0, -0.04, 0.0),
    "FRM": _S("forearm", "hand", 0.5, -0.02, 0.04, 0.0),
    "WRA": _S("hand", None, 0.0, 0.03, 0.02, 0.0),
    "WRB": _S("hand", None, 0.0, -0.03, 0.02, 0.0),
    "OWR": _S("hand", None, 0.0, -0.03, 0.02, 0.0),
    "IWR": _S("hand", None, 0.0, 0.03, 0.0, 0.0),
    "WRE": _S("hand", None, 0.0, 0.0, 0.035, 0.0),
    "IHAND": _S("hand", None, 0.0, 0.03, 0.0, -0.07),
    "OHAND": _S("hand", None, 0.0, -0.03, 0.01, -0.07),
    "FIN": _S("hand", None, 0.0, 0.0, 0.01, -0.10),
    "FWT": _S("pelvis", None, 0.0, 0.11, 0.12, 0.07),
    "MWT": _S("pelvis", None, 0.0, 0.0, 0.15, 0.07),
    "BWT": _S("pelvis", None, 0.0, -0.09, 0.07, 0.08),
    "HIP": _S("thigh", None, 0.0, 0.0, 0.08, -0.04),
    "THI": _S("thigh", "shin", 0.5, 0.02, 0.08, 0.0),
    "KNE": _S("shin", None, 0.0, 0.0, 0.05, 0.0),
    "KNI": _S("shin", None, 0.0, 0.0, -0.05, 0.0),
    "SHN": _S("shin", "foot", 0.5, 0.05, 0.0, 0.0),
    "ANK": _S("foot", None, 0.0, 0.0, 0.04, 0.0),
    "HEE": _S("foot", None, 0.0, -0.06, 0.0, -0.05),
    "HEL": _S("foot", None, 0.0, -0.06, 0.0, -0.05),
    "MT5": _S("toe", None, 0.0, -0.02, 0.045, -0.02),
    "MT1": _S("toe", None, 0.0, -0.02, -0.035, -0.02),
    "TOE": _S("toe", None, 0.0, 0.05, 0.0, -0.02),
}


def _sided(prefix: str, spec: MarkerSpec) -> MarkerSpec:
    side = prefix.lower()
    return spec._replace(
        role=f"{side}_{spec.role}" if spec.role != "head" and spec.role != "pelvis" else spec.role,
        to=None if spec.to is None else f"{side}_{spec.to}",
        lat=spec.lat if prefix == "L" else -spec.lat,
    )


MARKER_SPECS: dict[str, MarkerSpec] = dict(_CENTRAL)
for _suffix, _spec in _SIDED.items():
    for _p in ("L", "R"):
        MARKER_SPECS[_p + _suffix] = _sided(_p, _spec)

_CMU_SIDED = ("FHD", "BHD", "SHO", "UPA", "ELB", "FRM", "WRA", "WRB", "FIN",
              "FWT", "BWT", "THI", "KNE", "SHN", "ANK", "HEE", "TOE", "MT5")  # fmt: skip
_VICON_SIDED = ("FSH", "BSH", "UPA", "ELB", "IEL", "OWR", "IWR", "WRE", "IHAND", "OHAND",
                "FWT", "MWT", "BWT", "HIP", "KNE", "KNI", "SHN", "ANK", "HEL", "MT5", "MT1", "TOE")  # fmt: skip


def _both(suffixes: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(p + s for s in suffixes for p in ("L", "R"))


MARKER_SETS: dict[str, tuple[str, ...]] = {
    "cmu41": ("C7", "CLAV", "STRN", "T10", "RBAK") + _both(_CMU_SIDED),
    "vicon53": ("ARIEL", "LFHD", "LBHD", "RFHD", "RBHD", "C7", "T10", "CLAV", "STRN") + _both(_VICON_SIDED),
}
MARKER_SETS["ssm2_67"] = MARKER_SETS["vicon53"] + ("RBAK", "LBAK") + _both(("THI", "FRM", "FIN", "SHO", "WRA", "WRB"))
MARKER_SETS["bandai"] = MARKER_SETS["cmu41"]

# Per-set attachment changes (same reference position, another bone): set -> suffix -> spec.
_BANDAI_LIMB = {
    "ELB": _S("upperarm", "forearm", 1.0, -0.02, 0.04, 0.0),
    "WRA": _S("forearm", "hand", 1.0, 0.03, 0.02, 0.0),
    "WRB": _S("forearm", "hand", 1.0, -0.03, 0.02, 0.0),
    "KNE": _S("thigh", "shin", 1.0, 0.0, 0.05, 0.0),
    "ANK": _S("shin", "foot", 1.0, 0.0, 0.04, 0.0),
}
SET_OVERRIDES: dict[str, dict[str, MarkerSpec]] = {
    "bandai": {p + k: _sided(p, v) for k, v in _BANDAI_LIMB.items() for p in ("L", "R")},
}
# Two markers rigid on each of the eight limb bones of the `bandai` set (upper arm, forearm,
# thigh, shank per side): their distance is constant for any valid body.
LIMB_MARKER_PAIRS = tuple(
    (p + a, p + b) for p in ("L", "R") for a, b in (("UPA", "ELB"), ("FRM", "WRA"), ("THI", "KNE"), ("SHN", "ANK"))
)


def marker_spec(name: str, marker_set: str | None = None) -> MarkerSpec:
    """Returns the attachment of marker `name` (with `marker_set`'s override, if any)."""
    over = SET_OVERRIDES.get(marker_set or "", {})
    if name in over:
        return over[name]
    if name not in MARKER_SPECS:
        raise ValueError(f"marker {name!r} has no attachment in MARKER_SPECS")
    return MARKER_SPECS[name]
assert [len(MARKER_SETS[k]) for k in ("cmu41", "vicon53", "ssm2_67")] == [41, 53, 67]


def resolve_roles(names: tuple[str, ...]) -> dict[str, int]:
    """Returns role -> joint index for every role some alias of which is among `names`."""
    index = {n: i for i, n in enumerate(names)}
    out = {}
    for role, aliases in ROLE_ALIASES.items():
        for a in aliases:
            if a in index:
                out[role] = index[a]
                break
    return out
