"""Foot targets: swing feet lifted to the robot's stance height, contact feet locked and rolling.

In each contact run a foot gets one place and heading on the floor; within it the foot is
flat while the human's is, and otherwise rolls over its heel or toe pivot with the human's
pitch (:func:`feet_targets`). The lock weight raises the foot targets' weights in stance.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.motion.skeleton import JOINT_INDEX
from retarget.kinematics import so3_exp, so3_log
from retarget.robot_model import RobotModel
from retarget.stance import true_runs

STANCE_CLEARANCE = 0.001
"""Locked feet stand this high (m) above the floor (the solver's floor margin)."""
PITCH_SMOOTH_SECONDS = 0.05
"""Gaussian sigma (s) of a contact foot's pitch (flat, heel strike, toe-off) over time."""
LOCK_GAIN = 30.0
"""Weight multiplier of the foot targets during stance (locked feet)."""


def foot_heading_pitch(world: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Heading (yaw about +Z) and elevation (rad) of the ankle -> toe vector, (T,) each."""
    v = world[:, JOINT_INDEX[f"{side}_foot"]] - world[:, JOINT_INDEX[f"{side}_ankle"]]
    heading = np.arctan2(v[:, 1], v[:, 0])
    elevation = np.arctan2(v[:, 2], np.linalg.norm(v[:, :2], axis=1))
    return heading, elevation


def rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(angle), np.ones_like(angle)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def rot_y(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(angle), np.ones_like(angle)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def foot_pivots(robot: RobotModel, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Heel and toe pivots (3,) of a foot in its node frame: the centres of its rearmost and
    foremost sole points (the collision points within 3 mm of the sole, the foot flat, world +X
    forward). A foot rolling about a pivot keeps that point's height and place."""
    f = robot.feet[side]
    rot = robot.foot_flat_rot[side]
    world = f.points @ rot.T
    low = world[:, 2] - f.radius
    sole = low <= low.min() + 0.003
    x = world[:, 0]
    front = sole & (x >= x[sole].max() - 0.01)
    back = sole & (x <= x[sole].min() + 0.01)
    return f.points[back].mean(axis=0), f.points[front].mean(axis=0)


def feet_targets(
    robot: RobotModel,
    side: str,
    world: np.ndarray,
    fps: float,
    flat_stance: np.ndarray,
    contact: np.ndarray,
    heel: np.ndarray,
    toe: np.ndarray,
    alpha: np.ndarray,
    alpha_xy: np.ndarray,
    kp_pos: np.ndarray,
    kp_weight: np.ndarray,
    ori_kp: list[int],
    ori_rot: np.ndarray,
    ori_w: np.ndarray,
) -> None:
    """Lift swing-foot targets to the robot's stance height; in contact, a rigid rolling foot.

    Each contact run gets one place and heading. Within it the foot is flat while the human
    foot is flat, and otherwise pitches with the human foot about its heel pivot (toe up: a
    heel strike) or its toe pivot (heel up: a toe-off, tiptoes), the pivot fixed on the floor
    (:func:`foot_pivots`): the robot rolls over its sole instead of hovering or sliding.
    """
    ka = robot.keypoint_index(f"{side}_ankle")
    foot_node = robot.nodes[ka]
    same_node = [
        k
        for k in range(len(robot.joints))
        if robot.nodes[k] == foot_node and robot.keypoint_names[k] in (f"{side}_ankle", f"{side}_foot")
    ]
    rest_rot = robot.foot_flat_rot[side]  # the foot flat on the floor, facing +X
    flat_height = robot.foot_flat_height[side]  # its node's height then
    heading, elevation = foot_heading_pitch(world, side)
    ref = flat_stance if flat_stance.any() else contact
    flat = np.median(elevation[ref]) if ref.any() else np.median(elevation)
    # Swing: shift the foot keypoints vertically so the human stance height is the robot's.
    ankle_rest_h = flat_height + float((rest_rot @ robot.offsets[ka])[2])
    ref_h = kp_pos[ref, ka, 2] if ref.any() else np.sort(kp_pos[:, ka, 2])[: max(1, len(kp_pos) // 20)]
    lift = ankle_rest_h - float(np.median(ref_h))
    for k in same_node:
        kp_pos[:, k, 2] += lift
    pitch = -(elevation - flat)  # > 0: toe down (heel up)
    swing_rot = rot_z(heading) @ rot_y(pitch) @ rest_rot
    lock_rot = swing_rot.copy()
    lock_node = kp_pos[:, ka] - np.einsum("tij,j->ti", swing_rot, robot.offsets[ka])
    runs = true_runs(contact)
    if runs:
        # In contact: flat when both heel and toe are down, else rolling on the pivot that
        # the human's pitch puts on the floor (never rolling onto the lifted end).
        theta = np.where(heel & toe, 0.0, pitch)
        theta = np.where(toe & ~heel, np.maximum(theta, 0.0), theta)
        theta = np.where(heel & ~toe, np.minimum(theta, 0.0), theta)
        theta = np.where(contact, theta, pitch)
        # The flags switch within a frame; the pitch must not: smooth it over ~0.1 s (the
        # pivot follows its sign, and both pivots are on the floor when it is 0).
        if len(theta) > 2:
            theta = gaussian_filter1d(theta, PITCH_SMOOTH_SECONDS * fps, mode="nearest")
        c_heel, c_toe = foot_pivots(robot, side)
        pivot = np.where((theta > 0)[:, None], c_toe, c_heel)  # (T, 3) node frame
        frames = np.arange(len(world))
        starts = np.array([s for s, _ in runs])
        ends = np.array([e - 1 for _, e in runs])
        gap = np.maximum(starts[None, :] - frames[:, None], 0) + np.maximum(
            frames[:, None] - ends[None, :], 0
        )
        owner = np.argmin(gap, axis=1)  # every frame belongs to its nearest contact run
        height = flat_height + STANCE_CLEARANCE
        for i, (s, e) in enumerate(runs):
            sel = (owner == i) & (alpha_xy > 0)
            pick = np.arange(s, e)
            if flat_stance[s:e].any():
                pick = pick[flat_stance[s:e]]
            psi = np.angle(np.mean(np.exp(1j * heading[pick])))
            r_flat = rot_z(np.array(psi)) @ rest_rot
            r_roll = rot_z(np.full(len(world), psi)) @ rot_y(theta) @ rest_rot  # (T, 3, 3)
            # Place: where the human's own foot puts the flat foot's origin, averaged over the run.
            shift = np.einsum("tij,tj->ti", r_roll, pivot) - pivot @ r_flat.T  # node origin, flat - rolled
            origin = (
                kp_pos[pick, ka] - np.einsum("tij,j->ti", r_roll[pick], robot.offsets[ka]) + shift[pick]
            ).mean(axis=0)
            origin[2] = height
            lock_rot[sel] = r_roll[sel]
            lock_node[sel] = origin - shift[sel]
    a = np.stack([alpha_xy, alpha_xy, alpha], axis=1)
    for k in same_node:
        locked = lock_node + np.einsum("tij,j->ti", lock_rot, robot.offsets[k])
        kp_pos[:, k] = a * locked + (1 - a) * kp_pos[:, k]
        kp_weight[:, k] *= 1 + alpha * (LOCK_GAIN - 1)
    if ka in ori_kp:
        o = ori_kp.index(ka)
        delta = so3_log(np.swapaxes(swing_rot, -1, -2) @ lock_rot)
        ori_rot[:, o] = swing_rot @ so3_exp(delta * alpha[:, None])
        ori_w[:, o] *= 1 + alpha * (LOCK_GAIN - 1)
