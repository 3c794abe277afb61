"""Joint naming families of mocap skeletons and the mapping onto the 22 SMPL joints.

A :class:`SkeletonMap` says, for each of the 22 SMPL joints (``controlmm.motion.skeleton``), which
joint(s) of a source skeleton give its position: one name, or a weighted mean of several
(``{"Spine": 0.5, "Spine1": 0.5}``). Four naming families are recognised automatically:

========  ===========================================================================================
family    joint names (``Left*`` shown; ``Right*`` the same)
========  ===========================================================================================
lafan1    Hips, LeftUpLeg, LeftLeg, LeftFoot, LeftToe, Spine, Spine1, Spine2, Neck, Head,
          LeftShoulder, LeftArm, LeftForeArm, LeftHand (Ubisoft LAFAN1)
cmu       Hips, LHipJoint, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, LowerBack, Spine, Spine1, Neck,
          Neck1, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand (CMU mocap as BVH)
mixamo    ``mixamorig:`` + Hips, Spine, Spine1, Spine2, Neck, Head, LeftShoulder, LeftArm,
          LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase (Spine2 may be absent)
smpl      pelvis, left_hip, ..., right_wrist (this project, the SMPL body models), or the
          depth-first names Pelvis, L_Hip, L_Knee, L_Ankle, L_Toe, Torso, Spine, Chest, Neck, Head,
          L_Thorax, L_Shoulder, L_Elbow, L_Wrist (PHC / physics-simulation SMPL)
========  ===========================================================================================

Names are compared exactly first, then ignoring case and any namespace prefix (``mixamorig:``,
``mixamorig1:``, ``Character1_``-style prefixes are not stripped: only ``xxx:`` and ``mixamorig_``).
Where a family has fewer spine joints than SMPL's three, the middle one is the midpoint of its
neighbours. The BVH families' ``LeftShoulder`` is the SMPL collar, unless the file puts it on the
chest's centre line (as CMU conversions may: left and right shoulder joints closer than a quarter of
the shoulder width), where the collar is taken halfway to ``LeftArm`` (the clavicle's middle) so that
the two collars stay apart.

Any other skeleton needs a mapping file (JSON, :func:`load_skeleton_map`)::

    {"joints": {"pelvis": "Root", "left_hip": "L_UpperLeg", ..., "spine2": {"Chest": 0.5, "Waist": 0.5}},
     "joint_names": ["Root", "L_UpperLeg", ...],   # optional: column order of a position array
     "up": "z", "units": "cm", "fps": 120}          # optional: defaults for the file's conventions
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.errors import InputFileError
from controlmm.files import input_file
from controlmm.motion.skeleton import JOINT_NAMES, NUM_JOINTS

Sources = dict[str, float]
"""Source joint name -> weight (weights sum to 1)."""

MAPPING_DOC = "docs/motion-formats.md"
"""Where the mapping-file format is documented (named in error messages)."""

_PREFIX = re.compile(r"^(?:.*:|mixamorig\d*_)")


def normalise_name(name: str) -> str:
    """A joint name compared without case and without a namespace prefix (``mixamorig:Hips`` -> ``hips``)."""
    return _PREFIX.sub("", name.strip()).lower()


def _sided(left: str, right: str, table: dict[str, str | Sources]) -> dict[str, str | Sources]:
    """``table`` with ``{side}`` filled for the left and the right joints (names in SMPL order)."""
    out: dict[str, str | Sources] = {}
    for joint, value in table.items():
        for side, word in (("left", left), ("right", right)):
            if "{side}" in joint:
                key = joint.replace("{side}", side)
                if isinstance(value, str):
                    out[key] = value.replace("{S}", word)
                else:
                    out[key] = {k.replace("{S}", word): w for k, w in value.items()}
        if "{side}" not in joint:
            out[joint] = value
    return out


_HIPS_STYLE_LIMBS: dict[str, str | Sources] = {
    "pelvis": "Hips",
    "{side}_hip": "{S}UpLeg",
    "{side}_knee": "{S}Leg",
    "{side}_ankle": "{S}Foot",
    "neck": "Neck",
    "head": "Head",
    "{side}_collar": "{S}Shoulder",
    "{side}_shoulder": "{S}Arm",
    "{side}_elbow": "{S}ForeArm",
    "{side}_wrist": "{S}Hand",
}
_THREE_SPINES: dict[str, str | Sources] = {"spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2"}
_TWO_SPINES: dict[str, str | Sources] = {
    "spine1": "Spine",
    "spine2": {"Spine": 0.5, "Spine1": 0.5},
    "spine3": "Spine1",
}
_MID_CLAVICLES: dict[str, str | Sources] = _sided(
    "Left", "Right", {"{side}_collar": {"{S}Shoulder": 0.5, "{S}Arm": 0.5}}
)


def _table(*parts: dict[str, str | Sources], toe: str) -> dict[str, str | Sources]:
    merged: dict[str, str | Sources] = {"{side}_foot": toe}
    for part in parts:
        merged.update(part)
    return _sided("Left", "Right", merged)


@dataclass(frozen=True)
class Family:
    """A naming family: its name, the names that identify it, and its SMPL-22 table."""

    name: str
    table: dict[str, str | Sources]
    markers: tuple[str, ...] = ()  # normalised names that identify the family (any of them)
    prefix: str = ""  # a name prefix that identifies it (lower case, e.g. "mixamorig")
    needs_marker: bool = False  # chosen only when identified (its table is another family's)


SMPL_NAMES = dict(zip(JOINT_NAMES, JOINT_NAMES, strict=True))
_PHC: dict[str, str | Sources] = {
    "pelvis": "Pelvis",
    "{side}_hip": "{S}_Hip",
    "spine1": "Torso",
    "{side}_knee": "{S}_Knee",
    "spine2": "Spine",
    "{side}_ankle": "{S}_Ankle",
    "spine3": "Chest",
    "{side}_foot": "{S}_Toe",
    "neck": "Neck",
    "{side}_collar": "{S}_Thorax",
    "head": "Head",
    "{side}_shoulder": "{S}_Shoulder",
    "{side}_elbow": "{S}_Elbow",
    "{side}_wrist": "{S}_Wrist",
}
PHC_NAMES: dict[str, str] = {k: v for k, v in _sided("L", "R", _PHC).items() if isinstance(v, str)}
"""SMPL joint -> its name in the depth-first (PHC / physics-simulation) SMPL skeletons."""

FAMILIES: tuple[Family, ...] = (
    Family("smpl", dict(SMPL_NAMES), markers=("pelvis", "left_hip")),
    Family("smpl", dict(PHC_NAMES), markers=("l_hip", "l_thorax")),
    Family(
        "cmu",
        _table(_HIPS_STYLE_LIMBS, _TWO_SPINES, toe="{S}ToeBase"),
        markers=("lhipjoint", "lowerback", "neck1"),
        needs_marker=True,
    ),
    Family("lafan1", _table(_HIPS_STYLE_LIMBS, _THREE_SPINES, toe="{S}Toe"), markers=("lefttoe",)),
    Family("mixamo", _table(_HIPS_STYLE_LIMBS, _THREE_SPINES, toe="{S}ToeBase"), prefix="mixamorig"),
    Family("mixamo", _table(_HIPS_STYLE_LIMBS, _TWO_SPINES, toe="{S}ToeBase"), prefix="mixamorig"),
)
"""The recognised families, tried in this order (a family's markers or prefix break ties)."""


@dataclass(frozen=True)
class SkeletonMap:
    """Source joints of each SMPL joint, plus optional conventions of the source data.

    Attributes:
        name: the family (``lafan1``, ``cmu``, ``mixamo``, ``smpl``) or the mapping file's path.
        joints: SMPL joint name -> {source joint name: weight}, for all 22 joints.
        joint_names: the column order of a position array (mapping files only), else None.
        up: ``"y"``/``"z"`` declared by the mapping file, else None.
        units: unit declared by the mapping file (a name of ``controlmm.motion.formats.conventions.UNITS``
            or metres per unit), else None.
        fps: frame rate declared by the mapping file, else None.
    """

    name: str
    joints: dict[str, Sources]
    joint_names: tuple[str, ...] | None = None
    up: str | None = None
    units: str | float | None = None
    fps: float | None = None

    def missing(self, names: Sequence[str]) -> list[str]:
        """Source names this map needs that ``names`` lacks (in SMPL order, each once)."""
        index = _NameIndex(names)
        out: list[str] = []
        for sources in self.joints.values():
            for name in sources:
                if index.find(name) is None and name not in out:
                    out.append(name)
        return out

    def apply(self, names: Sequence[str], positions: np.ndarray) -> np.ndarray:
        """SMPL-22 positions (T, 22, 3) from a source skeleton's positions (T, J, 3) named ``names``."""
        index = _NameIndex(names)
        out = np.zeros((positions.shape[0], NUM_JOINTS, 3), dtype=np.float64)
        for j, joint in enumerate(JOINT_NAMES):
            for name, weight in self.joints[joint].items():
                k = index.find(name)
                if k is None:
                    raise InputFileError(
                        f"skeleton '{self.name}': no joint '{name}' for SMPL joint '{joint}'"
                    )
                out[:, j] += weight * positions[:, k]
        return out


class _NameIndex:
    """Find a joint by its exact name, else by its normalised name (when that is unique)."""

    def __init__(self, names: Sequence[str]) -> None:
        self.exact = {n: i for i, n in enumerate(names)}
        loose: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            loose.setdefault(normalise_name(n), []).append(i)
        self.loose = {k: v[0] for k, v in loose.items() if len(v) == 1}

    def find(self, name: str) -> int | None:
        if name in self.exact:
            return self.exact[name]
        return self.loose.get(normalise_name(name))


def _as_sources(table: Mapping[str, str | Sources]) -> dict[str, Sources]:
    return {j: ({v: 1.0} if isinstance(v, str) else dict(v)) for j, v in table.items()}


def detect_family(names: Sequence[str], positions: np.ndarray | None = None) -> SkeletonMap | None:
    """The naming family of a skeleton whose joints are ``names``, or None when none maps fully.

    With ``positions`` (T, J, 3), shoulder joints on the chest's centre line move the collars to the
    clavicles' middle (module docstring)."""
    normalised = {normalise_name(n) for n in names}
    lowered = [n.strip().lower() for n in names]
    best: tuple[int, int, Family] | None = None
    for rank, family in enumerate(FAMILIES):
        candidate = SkeletonMap(family.name, _as_sources(family.table))
        if candidate.missing(names):
            continue
        identified = any(m in normalised for m in family.markers) or (
            bool(family.prefix) and any(n.startswith(family.prefix) for n in lowered)
        )
        if family.needs_marker and not identified:
            continue
        key = (0 if identified else 1, rank, family)
        if best is None or key[:2] < best[:2]:
            best = key
    if best is None:
        return None
    table = dict(best[2].table)
    if positions is not None and _central_shoulders(names, positions, table):
        table.update(_MID_CLAVICLES)
    return SkeletonMap(best[2].name, _as_sources(table))


def _central_shoulders(names: Sequence[str], positions: np.ndarray, table: dict[str, str | Sources]) -> bool:
    """Whether the joints a table takes as the collars lie on the centre line (closer together than a
    quarter of the shoulder width)."""
    index = _NameIndex(names)
    picks = [table[k] for k in ("left_collar", "right_collar", "left_shoulder", "right_shoulder")]
    if not all(isinstance(p, str) for p in picks) or "Shoulder" not in str(picks[0]):
        return False
    found = [index.find(str(p)) for p in picks]
    if any(k is None for k in found):
        return False
    lc, rc, ls, rs = (positions[:, k] for k in found)
    collars = float(np.median(np.linalg.norm(lc - rc, axis=-1)))
    shoulders = float(np.median(np.linalg.norm(ls - rs, axis=-1)))
    return collars < 0.25 * shoulders


def closest_family(names: Sequence[str]) -> tuple[str, list[str]]:
    """The family needing the fewest missing joints for ``names``: (family name, missing names)."""
    scored = []
    for family in FAMILIES:
        missing = SkeletonMap(family.name, _as_sources(family.table)).missing(names)
        scored.append((len(missing), family.name, missing))
    _, name, missing = min(scored, key=lambda s: s[0])
    return name, missing


def unmapped_error(what: str, names: Sequence[str]) -> InputFileError:
    """The one-line error for a skeleton no family maps: its joints, the missing ones of the closest
    family, and the mapping file to write."""
    family, missing = closest_family(names)
    table = next(f.table for f in FAMILIES if f.name == family)
    needed = {n for v in _as_sources(table).values() for n in v}
    own = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
    if len(missing) < len(needed):
        shown = ", ".join(missing[:12]) + (f" and {len(missing) - 12} more" if len(missing) > 12 else "")
        why = f"the closest naming, {family}, lacks {shown}"
    else:
        why = f"they follow no known naming ({', '.join(dict.fromkeys(f.name for f in FAMILIES))})"
    return InputFileError(
        f"{what}: cannot map its {len(names)} joints ({own}) to the 22 SMPL joints: {why}; write a "
        f'mapping file {{"joints": {{"pelvis": "<your root joint>", "left_hip": ..., ...}}}} naming one of '
        f"your joints for each of the 22 SMPL joints ({', '.join(JOINT_NAMES)}) and pass it with "
        f"--skeleton-map FILE (see {MAPPING_DOC})"
    )


def load_skeleton_map(path: str | Path) -> SkeletonMap:
    """Read a mapping file (JSON, the module docstring); one-line errors name the bad entry."""
    path = input_file(path, "skeleton mapping file")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputFileError(f"skeleton mapping file '{path}' is not valid JSON ({exc})") from None
    return skeleton_map_from_dict(data, str(path))


def skeleton_map_from_dict(data: Any, source: str = "mapping") -> SkeletonMap:
    """A :class:`SkeletonMap` from the parsed mapping file ``data`` (see :func:`load_skeleton_map`)."""
    where = f"skeleton mapping '{source}'"
    if not isinstance(data, dict) or not isinstance(data.get("joints"), dict):
        raise InputFileError(f"{where}: expected an object with a 'joints' object (SMPL joint -> your joint)")
    table = data["joints"]
    unknown = [k for k in table if k not in JOINT_NAMES]
    if unknown:
        raise InputFileError(f"{where}: unknown SMPL joint '{unknown[0]}'; allowed: {', '.join(JOINT_NAMES)}")
    absent = [j for j in JOINT_NAMES if j not in table]
    if absent:
        raise InputFileError(
            f"{where}: no source joint for {', '.join(absent)}; all 22 SMPL joints are needed"
        )
    joints: dict[str, Sources] = {}
    for joint in JOINT_NAMES:
        value = table[joint]
        if isinstance(value, str) and value:
            joints[joint] = {value: 1.0}
        elif isinstance(value, dict) and value and all(isinstance(k, str) for k in value):
            weights = {k: _weight(w, where, joint) for k, w in value.items()}
            total = sum(weights.values())
            if not total > 0:
                raise InputFileError(f"{where}: the weights of '{joint}' must sum to more than 0")
            joints[joint] = {k: w / total for k, w in weights.items()}
        else:
            raise InputFileError(
                f"{where}: '{joint}' must be a joint name or an object {{name: weight}}; got {value!r}"
            )
    names = data.get("joint_names")
    if names is not None and not (
        isinstance(names, list) and names and all(isinstance(n, str) for n in names)
    ):
        raise InputFileError(f"{where}: 'joint_names' must be a list of names (the array's column order)")
    up = data.get("up")
    if up is not None and up not in ("y", "z"):
        raise InputFileError(f'{where}: \'up\' must be "y" or "z"; got {up!r}')
    units = data.get("units")
    if units is not None and not isinstance(units, (str, int, float)):
        raise InputFileError(f"{where}: 'units' must be a unit name or metres per unit; got {units!r}")
    fps = data.get("fps")
    if fps is not None and not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise InputFileError(f"{where}: 'fps' must be a positive number; got {fps!r}")
    result = SkeletonMap(
        name=source,
        joints=joints,
        joint_names=tuple(names) if names else None,
        up=up,
        units=units,
        fps=float(fps) if fps is not None else None,
    )
    if result.joint_names is not None and result.missing(result.joint_names):
        raise InputFileError(
            f"{where}: 'joint_names' lacks {', '.join(result.missing(result.joint_names)[:8])}, "
            "which 'joints' uses"
        )
    return result


def _weight(value: Any, where: str, joint: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
        raise InputFileError(f"{where}: the weights of '{joint}' must be numbers >= 0; got {value!r}")
    return float(value)
