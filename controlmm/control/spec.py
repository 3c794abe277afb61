"""Spatial control specification: which joint should be where, at which frame.

JSON format (also a Python API)::

    {"coords": "human" | "world",
     "constraints": [
        {"joint": "right_wrist", "frame": 60, "position": [x, y, z]},
        {"joint": "pelvis", "frame_range": [0, 59], "positions": [[x, y, z], ...]}   # dense form
     ]}

``human`` = HumanML3D frame (Y up, metres, the motion starts at the origin facing +Z, +X is the
person's left); ``world`` = MuJoCo world (Z up) used by scenes and robots, converted to the
human frame through a :class:`controlmm.frames.HumanToWorld` (the identity placement when none
is given). Joints are SMPL names (``controlmm.motion.skeleton.JOINT_NAMES``) or indices 0..21.
Frames are 0-based motion frames at 20 fps; ``frame_range`` is inclusive at both ends and needs
one position per frame.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.errors import ControlMMError, InputFileError
from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_NAMES, NUM_JOINTS, joint_index

COORDS = ("human", "world")


@dataclass(frozen=True)
class Constraint:
    """One joint at one frame at one position (in the spec's coordinates, metres)."""

    joint: int
    frame: int
    position: tuple[float, float, float]

    @property
    def joint_name(self) -> str:
        return JOINT_NAMES[self.joint]


@dataclass(frozen=True)
class ControlSpec:
    """A validated list of point constraints in ``coords`` coordinates."""

    constraints: tuple[Constraint, ...]
    coords: str = "human"
    source: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if self.coords not in COORDS:
            raise ControlMMError(f"coords must be one of {', '.join(COORDS)}; got '{self.coords}'")
        seen: set[tuple[int, int]] = set()
        for c in self.constraints:
            key = (c.joint, c.frame)
            if key in seen:
                raise ControlMMError(f"duplicate constraint for joint '{c.joint_name}' at frame {c.frame}")
            seen.add(key)

    # ----------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Any) -> ControlSpec:
        """Parse and validate the JSON structure (see the module docstring)."""
        if not isinstance(data, dict):
            raise ControlMMError(f"a control spec must be a JSON object; got {type(data).__name__}")
        unknown = set(data) - {"coords", "constraints"}
        if unknown:
            raise ControlMMError(
                f"unknown control-spec keys: {', '.join(sorted(unknown))}; allowed: coords, constraints"
            )
        coords = data.get("coords", "human")
        items = data.get("constraints")
        if not isinstance(items, list):
            raise ControlMMError("control spec needs a 'constraints' list")
        out: list[Constraint] = []
        for k, item in enumerate(items):
            out.extend(_parse_item(item, k))
        return cls(tuple(out), coords=str(coords), source=data)

    @classmethod
    def load(cls, path: str | Path) -> ControlSpec:
        """Read a JSON control spec file."""
        path = Path(path)
        if not path.is_file():
            raise InputFileError(f"control spec '{path}' does not exist")
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputFileError(f"control spec '{path}' is not valid JSON ({exc})") from exc
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable form with one point constraint per entry."""
        return {
            "coords": self.coords,
            "constraints": [
                {"joint": c.joint_name, "frame": c.frame, "position": list(c.position)}
                for c in self.constraints
            ],
        }

    # ----------------------------------------------------------------------------------
    @property
    def last_frame(self) -> int:
        return max((c.frame for c in self.constraints), default=-1)

    def check_length(self, num_frames: int) -> None:
        """Raise a one-line error if a constraint lies outside a motion of ``num_frames`` frames."""
        for c in self.constraints:
            if c.frame >= num_frames:
                raise ControlMMError(
                    f"constraint on '{c.joint_name}' at frame {c.frame} is outside the motion "
                    f"(frames 0..{num_frames - 1})"
                )

    def human_positions(self, transform: HumanToWorld | None = None) -> np.ndarray:
        """Constraint positions in the human frame, (K, 3) float64."""
        pos: np.ndarray = np.array([c.position for c in self.constraints], dtype=np.float64).reshape(-1, 3)
        if self.coords == "world":
            # to_human maps an ndarray to an ndarray; asarray states it (no copy).
            pos = np.asarray((transform or HumanToWorld()).to_human(pos))
        return pos

    def dense(self, num_frames: int, transform: HumanToWorld | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Targets (T, 22, 3) in the human frame (zeros where free) and a bool mask (T, 22)."""
        self.check_length(num_frames)
        targets = np.zeros((num_frames, NUM_JOINTS, 3), dtype=np.float32)
        mask = np.zeros((num_frames, NUM_JOINTS), dtype=bool)
        for c, p in zip(self.constraints, self.human_positions(transform), strict=True):
            targets[c.frame, c.joint] = p
            mask[c.frame, c.joint] = True
        return targets, mask

    def pinned_frame0_warnings(self, transform: HumanToWorld | None = None, tol: float = 0.01) -> list[str]:
        """Warnings for pelvis targets at frame 0 away from the origin (unreachable by design)."""
        warnings = []
        for c, p in zip(self.constraints, self.human_positions(transform), strict=True):
            if c.joint == 0 and c.frame == 0:
                off = float(np.hypot(p[0], p[2]))
                if off > tol:
                    warnings.append(
                        f"pelvis target at frame 0 is {off:.2f} m from the motion origin; the HumanML3D "
                        "representation pins frame 0 there, so it cannot be met"
                    )
        return warnings


def _position(value: Any, where: str) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ControlMMError(f"{where}: position must be 3 numbers; got {value!r}") from exc
    if arr.shape != (3,):
        raise ControlMMError(f"{where}: position must be 3 numbers [x, y, z]; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ControlMMError(f"{where}: position contains NaN/inf")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _frame(value: Any, where: str) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or value != int(value)
    ):
        raise ControlMMError(f"{where}: frame must be a whole number >= 0; got {value!r}")
    if value < 0:
        raise ControlMMError(f"{where}: frame must be >= 0; got {int(value)}")
    return int(value)


def _parse_item(item: Any, k: int) -> list[Constraint]:
    where = f"constraint {k}"
    if not isinstance(item, dict):
        raise ControlMMError(f"{where} must be an object with joint/frame/position")
    if "joint" not in item:
        raise ControlMMError(f"{where} has no 'joint'")
    joint = joint_index(item["joint"])
    if "frame_range" in item or "positions" in item:
        extra = set(item) - {"joint", "frame_range", "positions"}
        if extra:
            raise ControlMMError(f"{where}: unexpected keys {', '.join(sorted(extra))} in the dense form")
        rng = item.get("frame_range")
        if not isinstance(rng, (list, tuple)) or len(rng) != 2:
            raise ControlMMError(f"{where}: frame_range must be [start, end] (inclusive)")
        start, end = _frame(rng[0], where), _frame(rng[1], where)
        if end < start:
            raise ControlMMError(f"{where}: frame_range end {end} is before start {start}")
        positions = item.get("positions")
        try:
            arr = np.asarray(positions, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ControlMMError(f"{where}: positions must be a list of [x, y, z]") from exc
        if arr.shape != (end - start + 1, 3):
            raise ControlMMError(
                f"{where}: positions must have shape ({end - start + 1}, 3) for frames {start}..{end}; "
                f"got {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ControlMMError(f"{where}: positions contain NaN/inf")
        return [
            Constraint(joint, f, (float(p[0]), float(p[1]), float(p[2])))
            for f, p in zip(range(start, end + 1), arr, strict=True)
        ]
    extra = set(item) - {"joint", "frame", "position"}
    if extra:
        raise ControlMMError(
            f"{where}: unexpected keys {', '.join(sorted(extra))}; allowed: joint, frame, position"
        )
    if "frame" not in item or "position" not in item:
        raise ControlMMError(f"{where} needs 'frame' and 'position' (or 'frame_range' and 'positions')")
    return [Constraint(joint, _frame(item["frame"], where), _position(item["position"], where))]
