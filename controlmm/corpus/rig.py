"""The body rig of the procedural corpus: rest directions, rotations and two-bone IK.

Body frame: x is the person's left, y up, z forward (the HumanML3D frame of a person
facing +Z). A heading ``yaw`` (radians) turns the body about +Y; positive yaw turns the
person to their left (counter-clockwise seen from above). Bone lengths are the HumanML3D
reference lengths (:data:`controlmm.motion.skeleton.BONE_LENGTHS`); every joint is placed
as parent + unit direction x reference length, so bones never stretch.
"""

from __future__ import annotations

import numpy as np

from controlmm.motion.skeleton import BONE_LENGTHS


def unit(v: np.ndarray) -> np.ndarray:
    """Normalise vectors along the last axis (zero vectors stay zero)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def rot_x(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about +X, angles (...,) -> (..., 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about +Y (yaw; positive turns +Z towards +X, i.e. left), (..., 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about +Z, angles (...,) -> (..., 3, 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def rot_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation about unit axes (..., 3) by angles (...,) -> (..., 3, 3)."""
    axis = unit(axis)
    angle = np.asarray(angle, dtype=np.float64)
    x, y, z = np.moveaxis(axis, -1, 0)
    c, s = np.cos(angle), np.sin(angle)
    C = 1.0 - c
    return np.stack(
        [
            np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], -1),
            np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], -1),
            np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], -1),
        ],
        -2,
    )


def body_rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Orientation of a body segment (T, 3, 3) = yaw about Y, then forward pitch, then side roll.

    ``pitch`` > 0 tilts the segment's up axis forward (+z); ``roll`` > 0 tilts it towards the
    person's left (+x).
    """
    return rot_y(yaw) @ rot_x(pitch) @ rot_z(-np.asarray(roll, dtype=np.float64))


def apply(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors: rot (..., 3, 3) @ v (..., 3) -> (..., 3)."""
    return np.einsum("...ij,...j->...i", rot, np.broadcast_to(v, rot.shape[:-1]))


def heading_vectors(yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward (sin, 0, cos) and left (cos, 0, -sin) unit vectors of headings (...,)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    zero = np.zeros_like(yaw)
    fwd = np.stack([np.sin(yaw), zero, np.cos(yaw)], -1)
    left = np.stack([np.cos(yaw), zero, -np.sin(yaw)], -1)
    return fwd, left


def two_bone_ik(
    root: np.ndarray, target: np.ndarray, pole: np.ndarray, l1: float, l2: float, max_reach: float = 0.998
) -> tuple[np.ndarray, np.ndarray]:
    """Analytic two-bone IK (thigh/shin or upper arm/forearm), vectorised over frames.

    Args:
        root: (T, 3) hip or shoulder positions.
        target: (T, 3) wanted ankle or wrist positions.
        pole: (T, 3) direction the middle joint (knee, elbow) bends towards.
        l1, l2: bone lengths (m).
        max_reach: the limb never straightens beyond this fraction of l1 + l2 (no lock,
            no hyper-extension: the middle joint always lies on the pole side).

    Returns:
        mid: (T, 3) knee/elbow; end: (T, 3) ankle/wrist (moved onto the reachable range
        along root -> target when the target is too far or too close).
    """
    d_vec = target - root
    dist = np.linalg.norm(d_vec, axis=-1)
    lo = abs(l1 - l2) + 1e-3
    dist_c = np.clip(dist, lo, max_reach * (l1 + l2))
    u = unit(d_vec)
    v = pole - (pole * u).sum(-1, keepdims=True) * u
    v_norm = np.linalg.norm(v, axis=-1, keepdims=True)
    # Degenerate pole (parallel to the limb): fall back to any perpendicular direction.
    fallback = unit(np.cross(u, np.array([1.0, 0.0, 0.0])))
    v = np.where(v_norm > 1e-6, v / np.maximum(v_norm, 1e-12), fallback)
    x = (l1 * l1 - l2 * l2 + dist_c * dist_c) / (2.0 * dist_c)
    y = np.sqrt(np.maximum(l1 * l1 - x * x, 0.0))
    mid = root + u * x[:, None] + v * y[:, None]
    end = root + u * dist_c[:, None]
    return mid, end


# Bone lengths (m) of the reference skeleton, by name.
L = BONE_LENGTHS
THIGH = {"left": float(L[4]), "right": float(L[5])}
SHIN = {"left": float(L[7]), "right": float(L[8])}
FOOT = {"left": float(L[10]), "right": float(L[11])}
UPPER_ARM = {"left": float(L[18]), "right": float(L[19])}
FOREARM = {"left": float(L[20]), "right": float(L[21])}
SIDE_SIGN = {"left": 1.0, "right": -1.0}
"""+1 for the left side (+x in the body frame), -1 for the right."""

# Rest directions in the body frame (x left, y up, z forward) of an upright, relaxed person.
# Designed so that the neck sits ~0.52 m and the head ~0.60 m above the pelvis, the
# shoulders ~0.40 m above it and 0.40 m apart (HumanML3D standing proportions).
REST = {
    1: unit(np.array([0.56, -0.82, -0.08])),  # left_hip (from pelvis)
    2: unit(np.array([-0.56, -0.82, -0.08])),  # right_hip
    3: unit(np.array([0.0, 0.97, -0.24])),  # spine1
    6: unit(np.array([0.0, 0.96, 0.28])),  # spine2
    9: unit(np.array([0.0, 0.85, 0.53])),  # spine3
    12: unit(np.array([0.0, 0.99, -0.12])),  # neck
    15: unit(np.array([0.0, 0.64, 0.77])),  # head
    13: unit(np.array([0.55, 0.80, -0.20])),  # left_collar (from spine3)
    14: unit(np.array([-0.55, 0.80, -0.20])),  # right_collar
    16: unit(np.array([0.97, -0.08, -0.14])),  # left_shoulder (from collar)
    17: unit(np.array([-0.97, -0.08, -0.14])),  # right_shoulder
}

HIP_INDEX = {"left": 1, "right": 2}
KNEE_INDEX = {"left": 4, "right": 5}
ANKLE_INDEX = {"left": 7, "right": 8}
TOE_INDEX = {"left": 10, "right": 11}
COLLAR_INDEX = {"left": 13, "right": 14}
SHOULDER_INDEX = {"left": 16, "right": 17}
ELBOW_INDEX = {"left": 18, "right": 19}
WRIST_INDEX = {"left": 20, "right": 21}


def hip_offset(side: str) -> np.ndarray:
    """Pelvis -> hip vector in the pelvis frame (3,)."""
    return REST[HIP_INDEX[side]] * L[HIP_INDEX[side]]
