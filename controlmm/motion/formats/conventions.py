"""The conventions of imported positions: which axis is up, the length unit, left/right, body size.

Imported SMPL-22 positions (T, 22, 3) in the source's axes and units are brought to this project's
convention (metres, Y up) by :func:`to_y_up_metres`:

* **Up axis**: declared (``"y"``/``"z"``) or detected as the axis along which the body points
  (pelvis -> neck plus ankles -> pelvis, averaged over the clip). Z-up data is turned Y up by the
  proper rotation (x, y, z) -> (y, z, x), the inverse of :mod:`controlmm.frames`' human -> world
  mapping, so left stays left.
* **Units**: the skeleton's size against the HumanML3D reference skeleton
  (:func:`controlmm.motion.skeleton.body_size_ratio`, 1.0 for a person in metres) picks the unit of
  :data:`UNITS` that makes it a person (0.55x to 1.8x the reference size); BVH files are measured
  this way (their units vary: LAFAN1 and Mixamo centimetres, CMU 1/0.45 inch). Position
  arrays (SMPL joints) are metres by definition: any other size is refused, naming the unit it looks
  like, unless the unit is declared.
* **Left/right**: the toes must point forward of the facing direction the hips and shoulders imply
  (HumanML3D's rule); otherwise left and right are swapped or the axes mirrored, and the import is
  refused rather than retargeted backwards.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controlmm.errors import ShapeError
from controlmm.motion.skeleton import BONE_LENGTHS, JOINT_INDEX, PARENTS, body_size_ratio

UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "cmu": 0.0254 / 0.45,
}
"""Length units (metres per unit). ``cmu``: the CMU mocap database's unit (its skeleton files say
``length 0.45`` in inches), kept by the usual CMU BVH conversions."""

UNIT_WORDS: dict[str, str] = {
    "m": "metres",
    "cm": "centimetres",
    "mm": "millimetres",
    "in": "inches",
    "cmu": "CMU units (1/0.45 inch)",
}

PERSON_SIZE = (0.55, 1.8)
"""Sizes (x the reference skeleton, in metres) accepted as a person when the unit is detected."""

UP_AXES = ("y", "z")
"""Up axes a caller can declare."""

# Proper rotations (rows: new x, y, z in the old axes) that bring each signed axis to +Y.
_TO_Y_UP: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "-y": np.diag([1.0, -1.0, -1.0]),
    "z": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
    "-z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "x": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    "-x": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}
_J = JOINT_INDEX

REFERENCE_JOINT_HEIGHT = float(
    BONE_LENGTHS[[_J["left_knee"], _J["left_ankle"]]].sum()
    + BONE_LENGTHS[[_J["spine1"], _J["spine2"], _J["spine3"], _J["neck"], _J["head"]]].sum()
)
"""Ankle joint -> head joint along the bones of the reference skeleton (m), standing straight."""


@dataclass(frozen=True)
class Conventions:
    """What :func:`to_y_up_metres` found or was told (recorded in the motion's metadata)."""

    up: str  # the source's up axis ("y", "z", "-y", ...)
    up_detected: bool
    units: str  # a name of UNITS, or "x<metres per unit>" for a declared factor
    metres_per_unit: float
    units_detected: bool
    joint_height_m: (
        float  # ankle -> head joint along the bones, metres (REFERENCE_JOINT_HEIGHT for HumanML3D)
    )
    size_vs_reference: float  # body_size_ratio in metres (1.0: the HumanML3D reference skeleton)

    def to_dict(self) -> dict[str, object]:
        return {
            "up": self.up,
            "up_detected": self.up_detected,
            "units": self.units,
            "metres_per_unit": self.metres_per_unit,
            "units_detected": self.units_detected,
            "joint_height_m": round(self.joint_height_m, 4),
            "size_vs_reference": round(self.size_vs_reference, 4),
        }


def detect_up(joints: np.ndarray, what: str) -> str:
    """The signed axis (``"y"``, ``"-z"``, ...) along which the body points, from (T, 22, 3)."""
    pelvis, neck = joints[:, _J["pelvis"]], joints[:, _J["neck"]]
    ankles = 0.5 * (joints[:, _J["left_ankle"]] + joints[:, _J["right_ankle"]])
    body = ((neck - pelvis) + (pelvis - ankles)).mean(axis=0)
    norm = float(np.linalg.norm(body))
    axis = int(np.argmax(np.abs(body)))
    if not norm > 0 or abs(body[axis]) < 0.6 * norm:
        raise ShapeError(
            f"{what}: cannot tell which axis is up (the body lies along no axis over the clip); "
            "pass --up y or --up z"
        )
    return ("" if body[axis] > 0 else "-") + "xyz"[axis]


def parse_units(units: str | float) -> tuple[str, float]:
    """(name, metres per unit) of a declared unit: a name of :data:`UNITS` or a positive factor."""
    if isinstance(units, str) and units in UNITS:
        return units, UNITS[units]
    try:
        factor = float(units)
    except (TypeError, ValueError):
        raise ShapeError(
            f"unknown unit {units!r}; allowed: {', '.join(UNITS)} or metres per unit (e.g. 0.01)"
        ) from None
    if not (np.isfinite(factor) and factor > 0):
        raise ShapeError(f"metres per unit must be a positive number; got {units!r}")
    return f"x{factor:g}", factor


def guess_units(ratio: float) -> tuple[str, float] | None:
    """The unit of :data:`UNITS` that makes a skeleton of size ``ratio`` (in its own units) a person."""
    lo, hi = PERSON_SIZE
    fits = [(abs(np.log(ratio * f)), name, f) for name, f in UNITS.items() if lo <= ratio * f <= hi]
    if not fits:
        return None
    _, name, factor = min(fits)
    return name, factor


def to_y_up_metres(
    joints: np.ndarray,
    what: str,
    *,
    up: str | None = None,
    units: str | float | None = None,
    detect_units: bool = True,
) -> tuple[np.ndarray, Conventions]:
    """SMPL-22 positions (T, 22, 3) in the source's axes/units -> metres, Y up; and what was applied.

    ``up``: ``"y"``/``"z"`` or None (detect). ``units``: a unit name, metres per unit, or None: detected
    from the skeleton's size when ``detect_units`` (BVH), else the positions must be metres (position
    arrays) and a one-line error names the unit they look like.
    """
    joints = np.asarray(joints, dtype=np.float64)
    ratio = body_size_ratio(joints)
    if not (np.isfinite(ratio) and ratio > 0):
        raise ShapeError(f"{what}: the skeleton has no size (every bone has length 0)")
    if units is not None:
        unit_name, factor = parse_units(units)
        unit_detected = False
    else:
        guess = guess_units(ratio)
        lo, hi = PERSON_SIZE
        if not detect_units and not lo <= ratio <= hi:
            hint = f": it looks like {UNIT_WORDS[guess[0]]}; pass --units {guess[0]}" if guess else ""
            raise ShapeError(
                f"{what}: the skeleton is {ratio:.3g}x the size of a person in metres and position "
                f"arrays carry no unit{hint} (allowed: {', '.join(UNITS)} or metres per unit)"
            )
        if guess is None:
            raise ShapeError(
                f"{what}: cannot tell the length unit (the skeleton is {ratio:.3g} units against "
                f"{lo:g}-{hi:g} for a person in metres); pass --units ({', '.join(UNITS)} or metres per unit)"
            )
        unit_name, factor = ("m", 1.0) if not detect_units else guess
        unit_detected = detect_units
    if up is not None and up not in UP_AXES:
        raise ShapeError(f"unknown up axis {up!r}; allowed: {', '.join(UP_AXES)}")
    signed = up if up is not None else detect_up(joints, what)
    out = joints @ _TO_Y_UP[signed].T * factor
    check_left_right(out, what)
    conv = Conventions(
        up=signed,
        up_detected=up is None,
        units=unit_name,
        metres_per_unit=factor,
        units_detected=unit_detected,
        joint_height_m=joint_height(out),
        size_vs_reference=ratio * factor,
    )
    return out, conv


def joint_height(joints: np.ndarray) -> float:
    """Ankle -> head joint along the bones (m): median bone lengths over frames, mean of both legs."""
    bones = np.median(np.linalg.norm(joints[:, 1:] - joints[:, list(PARENTS[1:])], axis=-1), axis=0)
    length = dict(zip(range(1, len(PARENTS)), bones, strict=True))
    legs = 0.5 * sum(length[_J[f"{s}_{b}"]] for s in ("left", "right") for b in ("knee", "ankle"))
    trunk = sum(length[_J[n]] for n in ("spine1", "spine2", "spine3", "neck", "head"))
    return float(legs + trunk)


def check_left_right(joints: np.ndarray, what: str) -> None:
    """A one-line error when the toes point backwards of the facing the hips and shoulders give
    (Y-up joints (T, 22, 3)): left and right are swapped, or the axes are mirrored."""
    across = (joints[:, _J["right_hip"]] - joints[:, _J["left_hip"]]) + (
        joints[:, _J["right_shoulder"]] - joints[:, _J["left_shoulder"]]
    )
    forward = np.cross(np.array([0.0, 1.0, 0.0]), across)
    toes = sum(joints[:, _J[f"{s}_foot"]] - joints[:, _J[f"{s}_ankle"]] for s in ("left", "right"))
    forward[:, 1] = 0.0
    toes[:, 1] = 0.0
    f = forward / np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-9)
    t = toes / np.maximum(np.linalg.norm(toes, axis=-1, keepdims=True), 1e-9)
    agreement = float(np.mean(np.sum(f * t, axis=-1)))
    if agreement < -0.3:
        raise ShapeError(
            f"{what}: the toes point backwards of the facing that the hips and shoulders give "
            f"(agreement {agreement:.2f}): left and right are swapped or the axes are mirrored; "
            "check the joint order or the mapping file's left/right joints"
        )


__all__ = [
    "Conventions",
    "PERSON_SIZE",
    "REFERENCE_JOINT_HEIGHT",
    "UNITS",
    "UP_AXES",
    "check_left_right",
    "detect_up",
    "guess_units",
    "joint_height",
    "parse_units",
    "to_y_up_metres",
]
