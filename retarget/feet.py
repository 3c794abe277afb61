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
        lo, hi = robot.lower[leg], robot.upper[leg]
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


SWING_TOLERANCE = 0.002
"""Swing feet may come this much (m) below their clearance at the output rate before being raised."""


def leg_joints(robot: RobotModel, side: str) -> np.ndarray:
    """Indices (into q) of the joints between the trunk and one foot."""
    other = {"left": "right", "right": "left"}[side]
    anc = robot.tree.ancestor
    return np.flatnonzero(anc[int(robot.feet[side].node)] & ~anc[int(robot.feet[other].node)])


def lift_swing_feet(robot: RobotModel, root_pos: np.ndarray, root_rot: np.ndarray, q: np.ndarray,
                    clearance: dict[str, np.ndarray], fps: float,
                    candidates: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Joint angles (T, nj) with swing feet raised back to their clearance at the output rate.

    The solver keeps a swing foot ``clearance`` high at the motion's frames; between them the
    resampled joints may swing the foot's lowest point (a toe sweeping past the floor) a few
    millimetres lower. Where a foot is more than :data:`SWING_TOLERANCE` below its clearance
    (only where the clearance asks for more than standing height), the needed rise is
    max-filtered and smoothed over ~0.2 s (never below the need) and the distal joints of the
    leg (knee and below) raise the foot's lowest point by it: one minimum-norm step per frame
    along that point's Jacobian, smoothed over time like the rise (a smooth correction adds
    no jerk), limits kept.

    Args:
        robot: the robot; root_pos (T, 3), root_rot (T, 3, 3), q (T, nj) at ``fps``.
        clearance: per side, (T,) minimum height of the foot's collision points (m).
        candidates: (T,) bool, the frames that may dip (default: all); only these (and the
            smoothing around them) are evaluated.

    Returns:
        (q, largest rise in m).
    """
    from scipy.ndimage import maximum_filter1d

    tree = robot.tree
    q = q.copy()
    worst = 0.0
    look = np.ones(len(q), dtype=bool) if candidates is None else np.asarray(candidates, dtype=bool)
    if not look.any():
        return q, 0.0
    r = max(1, int(round(0.05 * fps)))
    # frames that may need a correction: the candidates and the smoothing span around them
    span = maximum_filter1d(look.astype(np.int8), size=8 * r + 1, mode="nearest").astype(bool)
    idx = np.flatnonzero(span)
    poses = tree.forward(root_pos[idx], root_rot[idx], q[idx])
    for side in ("left", "right"):
        f = robot.feet[side]
        need_mask = (clearance[side] > 0.005) & look
        if not need_mask.any():
            continue
        leg = leg_joints(robot, side)
        distal = leg[len(leg) // 2:]  # knee and below (chain order: hip ... ankle)
        lo, hi = robot.lower[distal], robot.upper[distal]
        h = np.full(len(q), np.inf)
        h_idx, point = _lowest(poses, f)
        h[idx] = h_idx
        deficit = np.where(need_mask, clearance[side] - h, 0.0)
        if deficit.max() <= SWING_TOLERANCE:
            continue
        rise = maximum_filter1d(np.maximum(deficit, 0.0), size=4 * r + 1, mode="nearest")
        rise = gaussian_filter1d(rise, sigma=r, mode="nearest", truncate=3.0)
        rise = np.maximum(rise, np.maximum(deficit, 0.0))
        worst = max(worst, float(rise.max()))
        up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (len(idx), 3))
        jac = tree.directional_jacobian(poses, np.arange(len(idx)), np.full(len(idx), f.node), point, up)[:, 6 + distal]
        step = np.zeros((len(q), len(distal)))
        step[idx] = jac * (rise[idx] / np.maximum(np.sum(jac * jac, axis=1), 1e-9))[:, None]
        step = gaussian_filter1d(step, sigma=r / 2.0, axis=0, mode="nearest")
        q[:, distal] = np.clip(q[:, distal] + step, lo, hi)
    return q, worst


def _lowest(poses, f) -> tuple[np.ndarray, np.ndarray]:
    """Height (T,) of a foot's lowest collision point above z = 0 and that point (T, 3)."""
    pts = poses.pos[:, f.node, None, :] + np.einsum("tij,pj->tpi", poses.rot[:, f.node], f.points)
    low = pts[..., 2] - f.radius
    i = np.argmin(low, axis=1)
    t = np.arange(len(low))
    return low[t, i], pts[t, i]
