"""Where the solver starts and what its temporal terms measure the root against.

:func:`initial_guess` places the root on the human pelvis (position and pelvis frame) with
the joints at rest; :func:`reference_root` smooths that root position over time, the
reference of the velocity and acceleration terms (:mod:`retarget.costs.temporal`).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from retarget.robot_model import RobotModel
from retarget.targets import Targets, human_frames

INSIDE_RANGE = 0.5
"""Where an elbow joint (a joint of the elbow keypoint's body) rests at an end of its range,
the solver starts it this share of the range inside it: a straight elbow held at its limit
cannot bend the way the gradient does not point at first, nor the upper arm turn to the
plane the elbow should bend in (an outside humanoid's arm raised over the head on the real
clip stayed hanging, the wrist 73 cm from the human's). Only the elbow: a wrist's twist
started a quarter turn away folded the CMU humanoid's forearm into its thigh in a stoop."""

AT_LIMIT = 1e-3
"""A joint within this (rad or m) of an end of its range rests at it."""

REF_SMOOTH_SECONDS = 0.05
"""Gaussian sigma (s) of the human pelvis reference of the root's temporal terms."""


def initial_guess(robot: RobotModel, targets: Targets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Root from the pelvis target (position + pelvis frame), joints at the rest pose:
    (root_pos (T, 3), root_rot (T, 3, 3), q (T, nj))."""
    k = robot.keypoint_index("pelvis")
    frame = human_frames(targets.human_world)["pelvis"]
    rot = frame @ robot.rest.rot[0, 0]  # the rest pose turned by the pelvis frame
    pos = targets.kp_pos[:, k] - frame @ robot.rest_keypoints[k]
    q = np.tile(start_q(robot), (len(pos), 1))
    return pos, rot, q


def start_q(robot: RobotModel) -> np.ndarray:
    """(nj,) the rest pose with each elbow joint that rests at an end of its range moved
    ``INSIDE_RANGE`` of the range inside it."""
    q = robot.rest_q.astype(np.float64).copy()
    arm = np.zeros(len(q), dtype=bool)
    arm[elbow_joints(robot)] = True
    inside = INSIDE_RANGE * (robot.upper - robot.lower)
    low = arm & (q - robot.lower < AT_LIMIT)
    high = arm & (robot.upper - q < AT_LIMIT)
    q[low] = robot.lower[low] + inside[low]
    q[high] = robot.upper[high] - inside[high]
    return q


def elbow_joints(robot: RobotModel) -> list[int]:
    """Coordinates (indices into q) of the joints of each elbow keypoint's body."""
    tree, out = robot.tree, []
    for side in ("left", "right"):
        if robot.has_keypoint(f"{side}_elbow"):
            body = tree.node_body[int(robot.nodes[robot.keypoint_index(f"{side}_elbow")])]
            out += [int(j) for n, j in enumerate(tree.node_joint) if j >= 0 and tree.node_body[n] == body]
    return out


def reference_root(robot: RobotModel, targets: Targets) -> np.ndarray:
    """(T, 3) the root reference of the temporal terms: the initial guess's root position
    (from the human pelvis) smoothed over REF_SMOOTH_SECONDS against joint noise. The terms
    act on the root's deviation from it, so the robot's root may accelerate as the human's
    does (a jump's arc), but not on its own."""
    ref_pos = initial_guess(robot, targets)[0]
    if len(ref_pos) > 2:
        ref_pos = gaussian_filter1d(ref_pos, REF_SMOOTH_SECONDS * targets.fps, axis=0, mode="nearest")
    return ref_pos
