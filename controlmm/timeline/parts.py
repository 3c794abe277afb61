"""Body parts of a timeline: the 22 HumanML3D (SMPL body) joints in six groups.

| part | joints (index: name) |
|---|---|
| ``legs`` | 0 pelvis, 1 left_hip, 2 right_hip, 4 left_knee, 5 right_knee, 7 left_ankle, 8 right_ankle, |
| | 10 left_foot, 11 right_foot |
| ``torso`` | 3 spine1, 6 spine2, 9 spine3 |
| ``head`` | 12 neck, 15 head |
| ``left_arm`` | 13 left_collar, 16 left_shoulder, 18 left_elbow, 20 left_wrist |
| ``right_arm`` | 14 right_collar, 17 right_shoulder, 19 right_elbow, 21 right_wrist |
| ``whole_body`` | all 22 joints |

The five groups other than ``whole_body`` partition the skeleton (every joint is in exactly one).
The pelvis (the root) belongs to the legs: a ``legs`` (or ``whole_body``) track may move and turn the
body, and the other parts then keep their pose *relative to the pelvis* instead of their world
position (see :mod:`controlmm.timeline.signals`). The collars (clavicles) go with the arms: raising an
arm lifts them.
"""

from __future__ import annotations

from controlmm.errors import ControlMMError
from controlmm.motion.skeleton import NUM_JOINTS

BODY_PARTS: dict[str, tuple[int, ...]] = {
    "legs": (0, 1, 2, 4, 5, 7, 8, 10, 11),
    "torso": (3, 6, 9),
    "head": (12, 15),
    "left_arm": (13, 16, 18, 20),
    "right_arm": (14, 17, 19, 21),
    "whole_body": tuple(range(NUM_JOINTS)),
}
"""Part name -> joint indices (HumanML3D order)."""

ROOT_JOINT = 0

ATTACHMENT: dict[str, int] = {
    "legs": 0,
    "torso": 0,
    "head": 9,
    "left_arm": 9,
    "right_arm": 9,
    "whole_body": 0,
}
"""The joint a part hangs from (spine3 for the arms and head, the pelvis otherwise): a track's prompt
motion is followed relative to it (see :func:`controlmm.timeline.signals.prompt_entries`)."""

ALIASES: dict[str, str] = {
    "body": "whole_body",
    "full_body": "whole_body",
    "all": "whole_body",
    "lower_body": "legs",
    "arm_left": "left_arm",
    "arm_right": "right_arm",
}


def part_name(name: str) -> str:
    """Canonical part name: case-insensitive, spaces and hyphens read as underscores ("left arm")."""
    if not isinstance(name, str):
        raise ControlMMError(f"a body part must be a name; got {name!r}; allowed: {', '.join(BODY_PARTS)}")
    key = "_".join(name.strip().lower().replace("-", " ").split())
    key = ALIASES.get(key, key)
    if key not in BODY_PARTS:
        raise ControlMMError(f"unknown body part '{name}'; allowed: {', '.join(BODY_PARTS)}")
    return key


def part_joints(name: str) -> tuple[int, ...]:
    """Joint indices of a part (any spelling :func:`part_name` accepts)."""
    return BODY_PARTS[part_name(name)]


def moves_root(name: str) -> bool:
    """Whether a part holds the pelvis (so its track may move the whole body through space)."""
    return ROOT_JOINT in part_joints(name)
