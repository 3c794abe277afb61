"""Reference dimensions of the HumanML3D skeleton that the robots are measured against (metres).

The scale of a robot is its rest hip height above its soles over ``HUMAN_HIP_HEIGHT``
(:class:`retarget.robot_model.RobotModel`); an inferred mapping (:mod:`retarget.automap`)
places the pelvis, chest, head and toe points with ``HUMAN_OFFSETS`` times that scale.
"""

from __future__ import annotations

import numpy as np

from controlmm.motion.skeleton import BONE_LENGTHS, JOINT_INDEX

HUMAN_ANKLE_HEIGHT = 0.055
"""Height (m) of the HumanML3D ankle joint above the floor in stance (median of the real clip 012314)."""

HUMAN_HIP_HEIGHT = float(
    (BONE_LENGTHS[4] + BONE_LENGTHS[7] + BONE_LENGTHS[5] + BONE_LENGTHS[8]) / 2 + HUMAN_ANKLE_HEIGHT
)
"""Hip-joint height (m) of the HumanML3D reference skeleton standing straight (thigh + shank + ankle)."""

PELVIS_ABOVE_HIPS = 0.084
"""Height (m) of the pelvis joint above the hip joints' line on the reference skeleton."""

HUMAN_PELVIS_HEIGHT = HUMAN_HIP_HEIGHT + PELVIS_ABOVE_HIPS
"""Pelvis height (m) standing straight."""

HUMAN_OFFSETS: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 0.0, PELVIS_ABOVE_HIPS),
    "spine3": (-0.039, 0.0, -0.118),
    "head": (-0.029, 0.0, 0.197),
    "toe": (0.133, 0.0, -0.045),
}
"""Offsets (m; forward, left, up) of the pelvis from the hips' midpoint, of the chest (spine3)
and the head from the shoulders' midpoint and of the toe from the ankle: the real clip 012314
standing at its start (the toe: its flat right foot)."""

HUMAN_FOREARM = float(BONE_LENGTHS[JOINT_INDEX["left_wrist"]])
"""Elbow -> wrist length (m)."""
HUMAN_UPPER_ARM = float(BONE_LENGTHS[JOINT_INDEX["left_elbow"]])
"""Shoulder -> elbow length (m)."""
HUMAN_HALF_HAND = 0.06
"""Wrist -> palm centre (m): where a robot's hand without wrist joints holds what the wrist follows."""


SIZE_TOLERANCE = 0.02
"""A clip whose legs are within this fraction of the reference skeleton's is scaled as the
reference (HumanML3D and the corpus are on it exactly; generated motions within 0.3 %)."""


def size_ratio(joints: np.ndarray) -> float:
    """How much smaller (< 1) or larger the clip's human is than the reference skeleton, from
    its legs: ``HUMAN_HIP_HEIGHT`` over its own standing hip height (mean thigh + shank
    lengths over the clip + ``HUMAN_ANKLE_HEIGHT``), 1 within ``SIZE_TOLERANCE``. A robot
    retargets a recorded subject (OMOMO's, 5 % taller or 12 % shorter) at its scale times this,
    as holosoma-retargeting scales by the subject's height. joints: (T, 22, 3) metres."""
    j = np.asarray(joints, dtype=np.float64)
    legs = [
        ("left_hip", "left_knee"),
        ("left_knee", "left_ankle"),
        ("right_hip", "right_knee"),
        ("right_knee", "right_ankle"),
    ]
    length = (
        sum(
            float(np.linalg.norm(j[:, JOINT_INDEX[a]] - j[:, JOINT_INDEX[b]], axis=-1).mean())
            for a, b in legs
        )
        / 2
    )
    if not np.isfinite(length) or length <= 0:
        return 1.0
    ratio = HUMAN_HIP_HEIGHT / (length + HUMAN_ANKLE_HEIGHT)
    return 1.0 if abs(ratio - 1.0) <= SIZE_TOLERANCE else float(ratio)
