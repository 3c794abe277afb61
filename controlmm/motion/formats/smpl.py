"""SMPL-family joint-position arrays: which columns hold the 22 SMPL body joints.

The SMPL body models put the 22 body joints first, in HumanML3D's order, and append the rest:

==========  =====  ===========================================================================
layout      J      what follows the 22 body joints
==========  =====  ===========================================================================
smpl22      22     nothing (HumanML3D ``new_joints``, this project's ``.npy`` joints)
smpl        24     left hand, right hand
smplh       52     15 left-hand then 15 right-hand finger joints (AMASS SMPL+H, OMOMO)
smplx       55     jaw, left eye, right eye, then 15 + 15 finger joints (SMPL-X)
smpl-out    45     the SMPL model's output: 24 joints + 21 vertex landmarks (nose, eyes, ears, toes...)
smplh-out   73     the SMPL+H model's output: 52 joints + 21 vertex landmarks
smplx-out   127    the SMPL-X model's output: 55 joints + face and foot landmarks
==========  =====  ===========================================================================

Physics-simulation code (PHC, InterMimic, holosoma's OMOMO demo data) orders the same 24 / 52 joints
depth first instead: pelvis, the left leg (hip, knee, ankle, toe), the right leg, the spine (torso,
spine, chest, neck, head), then each arm (thorax, shoulder, elbow, wrist, hand or fingers). The two
orders are told apart by the skeleton itself (:func:`smpl_body_joints`): the right order gives
bones of constant length over the clip whose left and right sides match.

InterMimic's OMOMO files (a (T, 591) tensor per clip, as shipped in holosoma-retargeting's demo
data) hold the 52 depth-first SMPL-H joints in columns 162..317 (Z up, 30 fps).
"""

from __future__ import annotations

import numpy as np

from controlmm.errors import ShapeError
from controlmm.motion.formats.naming import PHC_NAMES
from controlmm.motion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS

BODY_FIRST_LAYOUTS: dict[int, str] = {
    22: "smpl22",
    24: "smpl",
    52: "smplh",
    55: "smplx",
    45: "smpl-out",
    73: "smplh-out",
    127: "smplx-out",
}
"""Joint count -> layout whose first 22 joints are the SMPL body joints in HumanML3D order."""


def _depth_first_names(hands: int) -> list[str]:
    """Joint names of the depth-first SMPL order with ``hands`` joints per hand (1: SMPL, 15: SMPL-H)."""
    fingers = [f"{f}{k}" for f in ("Index", "Middle", "Pinky", "Ring", "Thumb") for k in (1, 2, 3)]
    names = ["Pelvis"]
    for s in "LR":
        names += [f"{s}_Hip", f"{s}_Knee", f"{s}_Ankle", f"{s}_Toe"]
    names += ["Torso", "Spine", "Chest", "Neck", "Head"]
    for s in "LR":
        names += [f"{s}_Thorax", f"{s}_Shoulder", f"{s}_Elbow", f"{s}_Wrist"]
        names += [f"{s}_Hand"] if hands == 1 else [f"{s}_{f}" for f in fingers]
    return names


DEPTH_FIRST_LAYOUTS: dict[int, str] = {24: "smpl-depth-first", 52: "smplh-depth-first"}
_DEPTH_FIRST_INDEX: dict[int, list[int]] = {}
for _count, _hands in ((24, 1), (52, 15)):
    _names = _depth_first_names(_hands)
    _DEPTH_FIRST_INDEX[_count] = [_names.index(PHC_NAMES[j]) for j in JOINT_NAMES]

INTERMIMIC_WIDTH = 591
INTERMIMIC_COLUMNS = slice(162, 162 + 52 * 3)
INTERMIMIC_FPS = 30.0


def known_counts() -> list[int]:
    """The joint counts a position array may have without a mapping file."""
    return sorted(BODY_FIRST_LAYOUTS)


def skeleton_score(joints: np.ndarray) -> float:
    """How little a (T, 22, 3) candidate looks like a skeleton: relative spread of each bone's
    length over the frames plus the relative left/right difference of paired bones (0 for a rigid,
    symmetric skeleton)."""
    bones = np.linalg.norm(joints[:, 1:] - joints[:, list(PARENTS[1:])], axis=-1)  # (T, 21)
    mean = np.maximum(bones.mean(axis=0), 1e-9)
    spread = float(np.median(bones.std(axis=0) / mean))
    pairs = [
        (JOINT_NAMES.index(n), JOINT_NAMES.index(n.replace("left", "right")))
        for n in JOINT_NAMES
        if "left" in n
    ]
    sym = [abs(mean[a - 1] - mean[b - 1]) / (mean[a - 1] + mean[b - 1]) for a, b in pairs]
    return spread + float(np.median(sym))


def smpl_body_joints(positions: np.ndarray, what: str) -> tuple[np.ndarray, str]:
    """The 22 SMPL body joints (T, 22, 3) of an SMPL-family array (T, J, 3), and its layout name.

    A 24- or 52-joint array may be in the body-first or the depth-first order: the one whose
    22 joints form the more rigid and symmetric skeleton is taken.
    """
    count = positions.shape[1]
    if count not in BODY_FIRST_LAYOUTS:
        allowed = ", ".join(f"{c} ({BODY_FIRST_LAYOUTS[c]})" for c in known_counts())
        raise ShapeError(
            f"{what}: {count} joints per frame is not an SMPL-family layout; allowed: {allowed}; "
            "for any other skeleton give a mapping file with its joint names (--skeleton-map FILE)"
        )
    body_first = positions[:, :NUM_JOINTS]
    if count not in DEPTH_FIRST_LAYOUTS:
        return body_first, BODY_FIRST_LAYOUTS[count]
    depth_first = positions[:, _DEPTH_FIRST_INDEX[count]]
    if skeleton_score(depth_first) < skeleton_score(body_first):
        return depth_first, DEPTH_FIRST_LAYOUTS[count]
    return body_first, BODY_FIRST_LAYOUTS[count]
