"""The HumanML3D 22-joint SMPL skeleton: names, parents, chains, offsets.

Conventions (HumanML3D): metres, Y up, floor at y = 0, the body faces +Z at frame 0 and
+X is the body's left. Motion runs at 20 frames per second.
"""

from __future__ import annotations

import numpy as np

from controlmm.errors import ControlMMError, ShapeError

FPS: int = 20
"""HumanML3D frame rate (frames per second)."""

MAX_FRAMES: int = 196
"""Longest motion the models generate (9.8 s at 20 fps)."""

MIN_FRAMES: int = 40
"""Shortest motion kept by the HumanML3D loaders (2 s)."""

FEATURE_DIM: int = 263
"""Size of the HumanML3D per-frame feature vector."""

NUM_JOINTS: int = 22

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
"""Joint names in HumanML3D (SMPL body) order."""

JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
"""Parent index of each joint (-1 for the root)."""

KINEMATIC_CHAINS: tuple[tuple[int, ...], ...] = (
    (0, 2, 5, 8, 11),
    (0, 1, 4, 7, 10),
    (0, 3, 6, 9, 12, 15),
    (9, 14, 17, 19, 21),
    (9, 13, 16, 18, 20),
)
"""HumanML3D ``t2m_kinematic_chain``; the order matters (the spine before the arms)."""

RAW_OFFSETS: np.ndarray = np.array(
    [
        [0, 0, 0],
        [1, 0, 0],
        [-1, 0, 0],
        [0, 1, 0],
        [0, -1, 0],
        [0, -1, 0],
        [0, 1, 0],
        [0, -1, 0],
        [0, -1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [0, 0, 1],
        [0, 1, 0],
        [1, 0, 0],
        [-1, 0, 0],
        [0, 0, 1],
        [0, -1, 0],
        [0, -1, 0],
        [0, -1, 0],
        [0, -1, 0],
        [0, -1, 0],
        [0, -1, 0],
    ],
    dtype=np.float64,
)
"""Unit rest direction of the bone parent -> joint (HumanML3D ``t2m_raw_offsets``), (22, 3)."""

BONE_LENGTHS: np.ndarray = np.array(
    [
        0.0,
        0.1030740,
        0.1098835,
        0.1315683,
        0.3936233,
        0.3901882,
        0.1431903,
        0.4324335,
        0.4256438,
        0.0573647,
        0.1433816,
        0.1494192,
        0.2193602,
        0.1374869,
        0.1433830,
        0.1030391,
        0.1316141,
        0.1229842,
        0.2568398,
        0.2630920,
        0.2660116,
        0.2698759,
    ],
    dtype=np.float64,
)
"""Length (m) of the bone parent -> joint on the HumanML3D reference skeleton, (22,).

Measured on the real HumanML3D clip 012314 (constant over frames to 5e-7 m); every
processed HumanML3D clip shares these lengths.
"""

TARGET_OFFSETS: np.ndarray = RAW_OFFSETS * BONE_LENGTHS[:, None]
"""Reference-skeleton offsets (raw direction x bone length), (22, 3), metres."""

FACE_JOINTS: tuple[int, int, int, int] = (2, 1, 17, 16)
"""(right_hip, left_hip, right_shoulder, left_shoulder): used to find the facing direction."""

FOOT_JOINTS_LEFT: tuple[int, int] = (7, 10)
FOOT_JOINTS_RIGHT: tuple[int, int] = (8, 11)

CONTROL_JOINTS: tuple[int, ...] = (0, 10, 11, 15, 20, 21)
"""Joints of the ControlMM control branch and evaluation: pelvis, feet, head, wrists."""

LEFT_RIGHT_MIRROR: tuple[int, ...] = (
    0,
    2,
    1,
    3,
    5,
    4,
    6,
    8,
    7,
    9,
    11,
    10,
    12,
    14,
    13,
    15,
    17,
    16,
    19,
    18,
    21,
    20,
)
"""Index permutation that swaps left and right joints (for mirroring)."""


def joint_index(joint: str | int) -> int:
    """Return the index of a joint given by name or index; raise a one-line error otherwise."""
    if isinstance(joint, (int, np.integer)) and not isinstance(joint, bool):
        if 0 <= int(joint) < NUM_JOINTS:
            return int(joint)
        raise ControlMMError(f"joint index {joint} is out of range; allowed 0..{NUM_JOINTS - 1}")
    name = str(joint).strip().lower()
    if name in JOINT_INDEX:
        return JOINT_INDEX[name]
    if name.isdigit():
        return joint_index(int(name))
    raise ControlMMError(f"unknown joint '{joint}'; valid joints: {', '.join(JOINT_NAMES)}")


METRE_SCALE_RANGE: tuple[float, float] = (0.3, 3.0)
"""Sizes (x the reference skeleton) accepted as a person in metres: a child to a giant robot."""


def body_size_ratio(joints: np.ndarray) -> float:
    """Size of a skeleton (T, 22, 3) relative to the reference one: the median over bones of
    (median length over frames) / (reference bone length). 1.0 for a person in metres,
    100 for centimetres."""
    joints = np.asarray(joints, dtype=np.float64)
    bones = np.linalg.norm(joints[:, 1:] - joints[:, list(PARENTS[1:])], axis=-1)  # (T, 21)
    return float(np.median(np.median(bones, axis=0) / BONE_LENGTHS[1:]))


def check_metre_scale(joints: np.ndarray, what: str = "motion") -> None:
    """A one-line ShapeError unless ``joints`` (T, 22, 3) look like a person measured in metres."""
    ratio = body_size_ratio(joints)
    lo, hi = METRE_SCALE_RANGE
    if not lo <= ratio <= hi:
        hint = " (centimetres? divide by 100)" if 30 <= ratio <= 300 else ""
        raise ShapeError(
            f"{what}: the skeleton is {ratio:.3g}x the size of a person in metres{hint}; "
            f"joints must be in metres ({lo:g}x to {hi:g}x the reference skeleton)"
        )
