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

REF_SMOOTH_SECONDS = 0.05
"""Gaussian sigma (s) of the human pelvis reference of the root's temporal terms."""


def initial_guess(robot: RobotModel, targets: Targets) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Root from the pelvis target (position + pelvis frame), joints at the rest pose:
    (root_pos (T, 3), root_rot (T, 3, 3), q (T, nj))."""
    k = robot.keypoint_index("pelvis")
    frame = human_frames(targets.human_world)["pelvis"]
    rot = frame @ robot.rest.rot[0, 0]  # the rest pose turned by the pelvis frame
    pos = targets.kp_pos[:, k] - frame @ robot.rest_keypoints[k]
    q = np.tile(robot.rest_q, (len(pos), 1))
    return pos, rot, q


def reference_root(robot: RobotModel, targets: Targets) -> np.ndarray:
    """(T, 3) the root reference of the temporal terms: the initial guess's root position
    (from the human pelvis) smoothed over REF_SMOOTH_SECONDS against joint noise. The terms
    act on the root's deviation from it, so the robot's root may accelerate as the human's
    does (a jump's arc), but not on its own."""
    ref_pos = initial_guess(robot, targets)[0]
    if len(ref_pos) > 2:
        ref_pos = gaussian_filter1d(ref_pos, REF_SMOOTH_SECONDS * targets.fps, axis=0, mode="nearest")
    return ref_pos
