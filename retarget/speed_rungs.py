"""Joint speed limits in the output: where a joint turns faster than it may between two output
frames, the motion is solved again with that joint's velocity term stiffer around there.

``controlmm validate`` fails a joint turning faster than its speed limit
(:func:`retarget.actuators.joint_speed_limits`: the G1's and H1's published ones, 3 pi rad/s,
GMR's IK velocity limit, for the others), and a joint turning faster than its damping lets its
motor (:func:`retarget.actuators.damped_speed_limits`: the Apollo's torso yaw at 0.6 rad/s)
fails ``validate`` on the torque it needs; the rungs keep each joint under the lower of the
two. The solver tracks the human, whose arm may swing near that speed (corpus clip 000019: the
upper arms at 9.3 rad/s), and a robot's joints may have to turn faster than the human's limb to
follow it (JVRC-1's shoulder pitch at 10.0 rad/s there, at 30 fps). The speed rungs
(:func:`retarget.retarget_motion.retarget_motion`) multiply the velocity weight
(``Targets.speed_gain``) of each joint past its limit by SPEED_STEP on the solver's frames
within SPEED_SPREAD of the output steps too fast, up to SPEED_SOLVES times (a joint still or
newly too fast in the solve kept gets another step there: stiffening one joint alone by 100 at
once makes its neighbours turn faster instead), and keep a solve only if it turns no joint
faster relative to its limit than the one kept.
"""

from __future__ import annotations

import numpy as np

SPEED_STEP = 10.0
"""Factor by which each speed rung stiffens the velocity weight of a joint past its limit."""
SPEED_SOLVES = 3
"""Speed rungs at most (each one solve)."""
SPEED_SPREAD = 0.15
"""Seconds either side of an output step too fast whose solver frames get the factor."""


def speed_ratios(qpos: np.ndarray, fps: float, limits: np.ndarray) -> np.ndarray:
    """(T - 1, nj) each joint's speed between consecutive frames of ``qpos`` (T, nq) over its
    limit (``limits`` (nj,) rad/s)."""
    return np.abs(np.diff(np.asarray(qpos)[:, 7:], axis=0)) * fps / limits


def speed_gain(
    ratios: np.ndarray, fps: float, frames: int, src_fps: float, gain: np.ndarray | None
) -> np.ndarray:
    """(frames, nj) the velocity-weight factors of the solver's ``frames`` (at ``src_fps``):
    ``gain`` (the factors so far, None: 1) times SPEED_STEP for each joint on the frames within
    SPEED_SPREAD of an output step (``ratios`` (T - 1, nj) at ``fps``, :func:`speed_ratios`)
    past its limit, unchanged elsewhere."""
    out = np.ones((frames, ratios.shape[1])) if gain is None else gain.copy()
    steps = (np.arange(len(ratios)) + 0.5) / fps
    times = np.arange(frames) / src_fps
    for j in np.flatnonzero((ratios > 1.0).any(axis=0)):
        fast = steps[ratios[:, j] > 1.0]
        near = np.abs(times[:, None] - fast[None, :]).min(axis=1) <= SPEED_SPREAD
        out[near, j] *= SPEED_STEP
    return out
