"""Stance feet pinned in place after the solve (at the solver's frame rate).

The whole-sequence solve holds stance feet with a strong but soft lock, so a planted foot
may still wander by a few millimetres when the rest of the body pulls. Here every stance
frame moves that leg's own joints (those between the trunk and that foot) so that the foot
reaches its locked target: Gauss-Newton on the foot's position (and orientation, at 0.05
m/rad, for legs with six or more joints; a five-joint leg such as H1's keeps the solver's
foot orientation), all frames at once; a step that does not lower a frame's error is
undone. The correction is then faded out around each stance with the lock weight and
smoothed over time (Gaussian, sigma = 1 frame), so that pinning adds no jerk.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from retarget.kinematics import so3_log
from retarget.robot_model import RobotModel
from retarget.targets import Targets

PIN_L_ROT = 0.05
"""Metres per radian of foot orientation error when pinning (position first)."""


def pin_stance_feet(robot: RobotModel, targets: Targets, root_pos: np.ndarray, root_rot: np.ndarray,
                    q: np.ndarray, iterations: int = 2) -> np.ndarray:
    """Joint angles (T, nj) with stance feet moved onto their locked targets."""
    tree = robot.tree
    q = q.copy()
    other = {"left": "right", "right": "left"}
    for side in ("left", "right"):
        lock = targets.lock[side]
        frames = np.flatnonzero(targets.stance[side] & (lock >= 1.0))
        if len(frames) == 0:
            continue
        k = robot.keypoint_index(f"{side}_ankle")
        node = int(robot.nodes[k])
        leg = np.flatnonzero(tree.ancestor[node] & ~tree.ancestor[int(robot.feet[other[side]].node)])
        o = list(targets.ori_kp).index(k) if (k in targets.ori_kp and len(leg) >= 6) else None
        goal = targets.kp_pos[frames, k]
        goal_rot = targets.ori_rot[frames, o] if o is not None else None
        lo, hi = tree.lower[leg], tree.upper[leg]
        start = q[np.ix_(frames, leg)].copy()
        cur, best = start.copy(), start.copy()
        best_cost = np.full(len(frames), np.inf)
        base = q[frames].copy()
        for it in range(iterations + 1):
            base[:, leg] = cur
            poses = tree.forward(root_pos[frames], root_rot[frames], base)
            pt = tree.points(poses, np.array([node]), robot.offsets[k][None])
            res = pt[:, 0] - goal
            if goal_rot is not None:
                err = so3_log(poses.rot[:, node] @ np.swapaxes(goal_rot, -1, -2)) * PIN_L_ROT
                res = np.concatenate([res, err], axis=1)
            cost = np.sum(res * res, axis=1)
            better = cost < best_cost
            best[better], best_cost[better] = cur[better], cost[better]
            if it == iterations:
                break
            jac = tree.point_jacobian(poses, np.array([node]), pt)[:, 0][..., 6 + leg]  # (F, 3, nl)
            if goal_rot is not None:
                jr = tree.rotation_jacobian(poses, np.array([node]))[:, 0][..., 6 + leg] * PIN_L_ROT
                jac = np.concatenate([jac, jr], axis=1)
            jt = np.swapaxes(jac, 1, 2)
            step = np.linalg.solve(jt @ jac + 1e-5 * np.eye(len(leg)), -(jt @ res[..., None]))[..., 0]
            cur = np.clip(np.where(better[:, None], cur, best) + step, lo, hi)
        # Correction over all frames: exact in stance, faded by the lock weight around it, smoothed.
        delta = np.zeros((len(q), len(leg)))
        delta[frames] = best - start
        near = np.flatnonzero((lock > 0) & ~np.isin(np.arange(len(q)), frames))
        if len(near):
            nearest = frames[np.abs(near[:, None] - frames[None, :]).argmin(axis=1)]
            delta[near] = lock[near, None] * delta[nearest]
        delta = gaussian_filter1d(delta, sigma=1.0, axis=0, mode="nearest")
        q[:, leg] = np.clip(q[:, leg] + delta, lo, hi)
    return q
