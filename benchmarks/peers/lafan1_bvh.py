"""HumanML3D joints as a LAFAN1 BVH: the input GMR's ``bvh`` source expects.

GMR (github.com/YanjieZe/GMR) reads a BVH as Ubisoft LAFAN1: LAFAN1 joint names, centimetres,
Y up, and LAFAN1's bone frames. Its G1 targets are the positions of some joints and the global
orientations of some bones times a constant per-bone rotation that assumes LAFAN1's local axes,
so renaming an SMPL-22 file's joints is not enough (its rest frames are a T-pose's and its limb
twist is arbitrary: a 29-32 cm fit on 012314). Here each bone's global rotation is built from the positions:

* the pelvis and the chest: a frame from their left-right axis (hip joints; collars) and their
  upward bone (pelvis -> spine1; spine3 -> neck), relative to the same frame standing upright;
* thigh and shin: the bone direction, twisted so that the knee's hinge axis (thigh x shin) is
  their lateral axis; near a straight knee the hinge is undefined and the axis the pelvis would
  carry (the thigh swung from hanging down) takes over smoothly;
* upper arm and forearm: the same with the elbow (upper arm x forearm) and the chest;
* foot: the ankle -> toe direction, with no roll about it (world up as the second axis);
* hand: the forearm's rotation (SMPL-22 has no hand end).

Each rotation is taken relative to a reference pose - upright, facing forward, upper arms
hanging, elbows bent a right angle (forearms forward), knees straight, feet flat: the G1's zero
pose - in which LAFAN1's bone frames are :data:`REFERENCE_FRAMES` (bones along their local x).
Spine, Spine1, Neck, Head, the collars and the ankles carry the rotation of the pelvis, the chest
or the toe. Every joint has position channels, so the file reproduces the input positions exactly
whatever the frames (any bone lengths, also a generated clip's).

Checked through GMR itself (commit 4f9e8b7, real clip 012314 at 30 fps): a 5.1 cm G1 fit
(:func:`retarget.compare.similarity_fit`) and orientation targets its IK meets within 0-15 degrees
on average per bone, against 32 cm and 28-103 degrees for the same joints renamed only; the
constants below moved the fit by at most 0.3 cm (5.1-5.4 cm).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controlmm.motion.bvh import write_bvh
from controlmm.motion.quaternion import qbetween, quat_to_matrix
from controlmm.motion.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS

LAFAN1_NAMES: tuple[str, ...] = (
    "Hips",
    "LeftUpLeg",
    "RightUpLeg",
    "Spine",
    "LeftLeg",
    "RightLeg",
    "Spine1",
    "LeftFoot",
    "RightFoot",
    "Spine2",
    "LeftToe",
    "RightToe",
    "Neck",
    "LeftShoulder",
    "RightShoulder",
    "Head",
    "LeftArm",
    "RightArm",
    "LeftForeArm",
    "RightForeArm",
    "LeftHand",
    "RightHand",
)
"""LAFAN1's name of each SMPL-22 joint, in HumanML3D order (``LeftShoulder`` is the collar)."""

# Body directions in HumanML3D's axes (Y up, facing +Z, the person's left +X).
LEFT, UP, FORWARD = np.eye(3)
RIGHT, DOWN, BACK = -LEFT, -UP, -FORWARD

REFERENCE_FRAMES: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {
    "Hips": (UP, FORWARD, LEFT),
    "Spine2": (UP, FORWARD, LEFT),
    "UpLeg": (DOWN, FORWARD, RIGHT),
    "Leg": (DOWN, FORWARD, RIGHT),
    "Toe": (FORWARD, UP, RIGHT),
    "Arm": (DOWN, BACK, LEFT),
    "ForeArm": (FORWARD, DOWN, LEFT),
}
"""LAFAN1's bone frames in the reference pose: the world directions of each bone's local x, y, z
(both sides alike; ``Hand`` as ``ForeArm``)."""

PELVIS_TILT_DEG = 12.7
"""Backward tilt of pelvis -> spine1 from vertical when HumanML3D's skeleton stands upright."""
CHEST_TILT_DEG = 5.1
"""Backward tilt of spine3 -> neck from vertical standing upright."""
FOOT_PITCH_DEG = 18.5
"""Downward pitch of ankle -> toe with the foot flat (HumanML3D's skeleton: 17.7-19.1 degrees).

The three angles are medians over the first frames of the real clip 012314 and 40 corpus clips
(standing starts), taken in the pelvis's sagittal plane."""
HINGE_BLEND = 0.25
"""Weight of the parent-carried lateral axis against the hinge axis thigh x shin (length
sin(knee bend)): equal at about 14.5 degrees of bend, the hinge dominates above."""
UNITS_PER_METRE = 100.0
"""LAFAN1 files are in centimetres."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _frame(primary: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) with columns: the primary direction, the reference made
    orthogonal to it, and their cross product."""
    x = _unit(primary)
    y = _unit(reference - (reference * x).sum(-1, keepdims=True) * x)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _tilt_back(degrees: float) -> np.ndarray:
    """The up direction tilted backwards (about the left axis) by ``degrees``."""
    a = np.radians(degrees)
    return np.cos(a) * UP + np.sin(a) * BACK


def _relative(
    primary: np.ndarray, reference: np.ndarray, rest_primary: np.ndarray, rest_reference: np.ndarray
) -> np.ndarray:
    """Rotations (T, 3, 3) taking the frame of the reference pose to the observed one."""
    rest = _frame(rest_primary, rest_reference)
    return np.einsum("tij,kj->tik", _frame(primary, reference), rest)


def _hinged(
    upper: np.ndarray,
    lower: np.ndarray,
    parent: np.ndarray,
    rest: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (T, 3, 3) of the two bones of a hinge (hip-knee-ankle, shoulder-elbow-wrist).

    Args:
        upper, lower: bone vectors (T, 3); parent: the parent's rotation (T, 3, 3) from the reference
            pose; rest: the upper and lower bones' directions and the hinge axis (the direction of
            upper x lower as the joint bends) in the reference pose.
    """
    rest_upper, rest_lower, rest_hinge = rest
    hinge = np.cross(_unit(upper), _unit(lower))
    carried = np.einsum("tij,j->ti", parent, rest_upper)
    swing = quat_to_matrix(qbetween(carried, upper))
    fallback = np.einsum("tij,tjk,k->ti", swing, parent, rest_hinge)
    lateral = hinge + HINGE_BLEND * fallback
    return (
        _relative(upper, lateral, rest_upper, rest_hinge),
        _relative(lower, lateral, rest_lower, rest_hinge),
    )


def lafan1_rotations(joints: np.ndarray) -> np.ndarray:
    """Global rotations (T, 22, 3, 3) of LAFAN1's bone frames for HumanML3D joints (T, 22, 3)
    (metres, Y up; HumanML3D order, see the module docstring)."""
    j = np.asarray(joints, dtype=np.float64)
    t = j.shape[0]
    i = JOINT_INDEX
    ref = {name: np.stack(axes, axis=-1) for name, axes in REFERENCE_FRAMES.items()}
    pelvis = _relative(
        j[:, i["left_hip"]] - j[:, i["right_hip"]],
        j[:, i["spine1"]] - j[:, i["pelvis"]],
        LEFT,
        _tilt_back(PELVIS_TILT_DEG),
    )
    chest = _relative(
        j[:, i["left_collar"]] - j[:, i["right_collar"]],
        j[:, i["neck"]] - j[:, i["spine3"]],
        LEFT,
        _tilt_back(CHEST_TILT_DEG),
    )
    pitch = np.radians(FOOT_PITCH_DEG)
    rest_foot = np.cos(pitch) * FORWARD + np.sin(pitch) * DOWN
    glob = np.empty((t, NUM_JOINTS, 3, 3))
    for name in ("pelvis", "spine1"):
        glob[:, i[name]] = pelvis @ ref["Hips"]
    for name in ("spine2", "spine3", "neck", "head", "left_collar", "right_collar"):
        glob[:, i[name]] = chest @ ref["Spine2"]
    for side in ("left", "right"):
        thigh, shin = _hinged(
            j[:, i[f"{side}_knee"]] - j[:, i[f"{side}_hip"]],
            j[:, i[f"{side}_ankle"]] - j[:, i[f"{side}_knee"]],
            pelvis,
            (DOWN, DOWN, LEFT),  # straight in the reference pose; the knee bends about the left axis
        )
        upper, fore = _hinged(
            j[:, i[f"{side}_elbow"]] - j[:, i[f"{side}_shoulder"]],
            j[:, i[f"{side}_wrist"]] - j[:, i[f"{side}_elbow"]],
            chest,
            (DOWN, FORWARD, RIGHT),
        )
        foot = _relative(j[:, i[f"{side}_foot"]] - j[:, i[f"{side}_ankle"]], UP, rest_foot, UP)
        glob[:, i[f"{side}_hip"]] = thigh @ ref["UpLeg"]
        glob[:, i[f"{side}_knee"]] = shin @ ref["Leg"]
        glob[:, i[f"{side}_ankle"]] = foot @ ref["Toe"]
        glob[:, i[f"{side}_foot"]] = foot @ ref["Toe"]
        glob[:, i[f"{side}_shoulder"]] = upper @ ref["Arm"]
        glob[:, i[f"{side}_elbow"]] = fore @ ref["ForeArm"]
        glob[:, i[f"{side}_wrist"]] = fore @ ref["ForeArm"]
    return glob


def write_lafan1_bvh(path: str | Path, joints: np.ndarray, fps: float) -> None:
    """Write HumanML3D joints (T, 22, 3) (metres, Y up) at ``fps`` as a LAFAN1 BVH: the project's
    BVH writer with LAFAN1's names, centimetres and the bone frames of :func:`lafan1_rotations`
    (every joint with position channels, so the positions come back exactly)."""
    pos = np.asarray(joints, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (NUM_JOINTS, 3) or len(pos) == 0:
        raise ValueError(f"joints must be (T, {NUM_JOINTS}, 3); got {pos.shape}")
    names = dict(zip(JOINT_NAMES, LAFAN1_NAMES, strict=True))
    write_bvh(path, pos, fps, names=names, units_per_metre=UNITS_PER_METRE, rotations=lafan1_rotations(pos))
