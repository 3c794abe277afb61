"""Stance feet pinned in place after the solve (at the solver's frame rate).

The whole-sequence solve holds stance feet with a strong but soft lock, so a planted foot
may still wander by a few millimetres when the rest of the body pulls. Here every stance
frame moves that leg's own joints (those between the trunk and that foot) so that the foot
reaches its locked target: Gauss-Newton on the foot's position (and orientation, at 0.05
m/rad, for legs with six or more joints; a five-joint leg such as H1's keeps the solver's
foot orientation), all frames at once; a step that does not lower a frame's error is
undone, and a frame whose correction would turn a joint by more than PIN_MAX_CHANGE keeps
the solver's pose (the lock is out of the leg's reach there). The correction is then faded
out around each stance with the lock weight and smoothed over time (Gaussian, sigma = 1
frame), so that pinning adds no jerk.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from retarget.foot_targets import FULL_LEG_JOINTS, leg_joints
from retarget.kinematics import Poses, quat_to_mat, so3_exp, so3_log
from retarget.robot_model import RobotModel
from retarget.targets import Targets

PIN_L_ROT = 0.05
"""Metres per radian of foot orientation error when pinning (position first)."""
PIN_MAX_CHANGE = 0.2
"""Largest joint change (rad) pinning may make in a frame; larger ones are not applied there."""


def pin_stance_feet(
    robot: RobotModel,
    targets: Targets,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q: np.ndarray,
    iterations: int = 2,
) -> np.ndarray:
    """Joint angles (T, nj) with stance feet moved onto their locked targets."""
    q = q.copy()
    for side in ("left", "right"):
        lock = targets.lock[side]
        frames = np.flatnonzero(targets.stance[side] & (lock >= 1.0))
        if len(frames) == 0:
            continue
        k = robot.keypoint_index(f"{side}_ankle")
        leg = leg_joints(robot, side)
        o = list(targets.ori_kp).index(k) if (k in targets.ori_kp and len(leg) >= FULL_LEG_JOINTS) else None
        goal_rot = targets.ori_rot[frames, o] if o is not None else None
        start = q[np.ix_(frames, leg)].copy()
        best = _pin_leg(
            robot,
            side,
            root_pos[frames],
            root_rot[frames],
            q[frames],
            targets.kp_pos[frames, k],
            goal_rot,
            iterations,
        )
        # Correction over all frames: exact in stance, faded by the lock weight around it, smoothed.
        # A frame whose leg would have to swing far (an unreachable lock: another IK branch)
        # keeps the solver's pose: pinning fixes millimetres, it does not re-pose a leg.
        delta = np.zeros((len(q), len(leg)))
        change = best - start
        delta[frames] = np.where((np.abs(change).max(axis=1) <= PIN_MAX_CHANGE)[:, None], change, 0.0)
        near = np.flatnonzero((lock > 0) & ~np.isin(np.arange(len(q)), frames))
        if len(near):
            nearest = frames[np.abs(near[:, None] - frames[None, :]).argmin(axis=1)]
            delta[near] = lock[near, None] * delta[nearest]
        delta = gaussian_filter1d(delta, sigma=1.0, axis=0, mode="nearest")
        q[:, leg] = np.clip(q[:, leg] + delta, robot.lower[leg], robot.upper[leg])
    return q


def _pin_leg(
    robot: RobotModel,
    side: str,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q: np.ndarray,
    goal: np.ndarray,
    goal_rot: np.ndarray | None,
    iterations: int,
) -> np.ndarray:
    """One leg's joints (F, nl) that bring its ankle keypoint to ``goal`` (F, 3) (and the foot
    to ``goal_rot`` (F, 3, 3) at PIN_L_ROT m/rad when given) for F frames of root_pos (F, 3),
    root_rot (F, 3, 3), q (F, nj): damped Gauss-Newton, a step that does not lower a frame's
    error undone, limits kept."""
    leg = leg_joints(robot, side)
    lo, hi = robot.lower[leg], robot.upper[leg]
    cur = q[:, leg].copy()
    best = cur.copy()
    best_cost = np.full(len(q), np.inf)
    base = q.copy()
    for it in range(iterations + 1):
        base[:, leg] = cur
        poses = robot.tree.forward(root_pos, root_rot, base)
        res, jac = _leg_residual(robot, side, poses, goal, goal_rot)
        cost = np.sum(res * res, axis=1)
        better = cost < best_cost
        best[better], best_cost[better] = cur[better], cost[better]
        if it == iterations:
            break
        cur = np.clip(np.where(better[:, None], cur, best) + _gauss_newton(res, jac), lo, hi)
    return best


def _leg_residual(
    robot: RobotModel, side: str, poses: Poses, goal: np.ndarray, goal_rot: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The ankle keypoint's residual (F, 3 or 6: position, then orientation at PIN_L_ROT m/rad)
    to ``goal`` / ``goal_rot`` and its Jacobian (F, 3 or 6, nl) in the leg's joints."""
    tree = robot.tree
    k = robot.keypoint_index(f"{side}_ankle")
    node = np.array([int(robot.nodes[k])])
    leg = leg_joints(robot, side)
    pt = tree.points(poses, node, robot.offsets[k][None])
    res = pt[:, 0] - goal
    jac = tree.point_jacobian(poses, node, pt)[:, 0][..., 6 + leg]  # (F, 3, nl)
    if goal_rot is not None:
        err = so3_log(poses.rot[:, node[0]] @ np.swapaxes(goal_rot, -1, -2)) * PIN_L_ROT
        res = np.concatenate([res, err], axis=1)
        jr = tree.rotation_jacobian(poses, node)[:, 0][..., 6 + leg] * PIN_L_ROT
        jac = np.concatenate([jac, jr], axis=1)
    return res, jac


def _gauss_newton(res: np.ndarray, jac: np.ndarray) -> np.ndarray:
    """Damped Gauss-Newton steps (F, n) for residuals (F, m) with Jacobians (F, m, n)."""
    jt = np.swapaxes(jac, 1, 2)
    return np.linalg.solve(jt @ jac + 1e-5 * np.eye(jac.shape[2]), -(jt @ res[..., None]))[..., 0]


HOLD_STILL = 0.002
HOLD_TURN = 0.02
"""A pinned foot is held between two solver frames where it moves less than this there (m, rad):
a planted foot, not one rolling onto its toes (whose spline path is its motion)."""
HOLD_MAX_CHANGE = 0.005
"""Largest joint change (rad) holding may make in a frame (the spline's wobble takes a few
milliradians; a larger change would add more joint jerk than it removes foot motion)."""


def hold_feet_between_frames(
    robot: RobotModel,
    targets: Targets,
    src_fps: float,
    src_qpos: np.ndarray,
    qpos: np.ndarray,
    fps: float,
) -> np.ndarray:
    """Joint angles (N, nj) of a resampled trajectory with pinned feet held between the solver's frames.

    The resampling splines the joints; the foot is a nonlinear function of them, so a foot
    pinned at two consecutive solver frames wobbles by ~0.1-0.3 mm in between (a few mm/s at
    30 fps). At every output frame between two solver frames where a foot is pinned (stance,
    lock 1) its ankle keypoint goes back onto the line between its two pinned places, and
    the foot onto the rotation between their orientations (legs of six or more joints): one
    Gauss-Newton step of the leg's joints, kept where no joint turns more than HOLD_MAX_CHANGE.

    Args:
        targets: the solve's targets at ``src_fps``; src_qpos (T, 7 + nj) the solve's qpos there.
        qpos: (N, 7 + nj) the resampled trajectory at ``fps`` (output frame n at n / fps s).
    """
    tree = robot.tree
    q = qpos[:, 7:].copy()
    src = tree.forward(src_qpos[:, :3], quat_to_mat(src_qpos[:, 3:7]), src_qpos[:, 7:])
    pos = np.arange(len(qpos)) * src_fps / fps
    i0 = np.clip(np.floor(pos + 1e-9).astype(int), 0, len(src_qpos) - 1)
    i1 = np.minimum(i0 + 1, len(src_qpos) - 1)
    w = np.clip(pos - i0, 0.0, 1.0)
    between = w > 1e-6
    held: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]] = {}
    for side in ("left", "right"):
        pinned = targets.stance[side] & (targets.lock[side] >= 1.0)
        frames = np.flatnonzero(between & pinned[i0] & pinned[i1])
        k = robot.keypoint_index(f"{side}_ankle")
        node = int(robot.nodes[k])
        place = tree.points(src, np.array([node]), robot.offsets[k][None])[:, 0]
        a, b = i0[frames], i1[frames]
        turn = np.linalg.norm(so3_log(np.swapaxes(src.rot[a, node], -1, -2) @ src.rot[b, node]), axis=-1)
        still = (np.linalg.norm(place[b] - place[a], axis=-1) < HOLD_STILL) & (turn < HOLD_TURN)
        frames, a, b = frames[still], a[still], b[still]
        if len(frames) == 0:
            continue
        t = w[frames, None]
        goal_rot = None
        if len(leg_joints(robot, side)) >= FULL_LEG_JOINTS:
            ra, rb = src.rot[a, node], src.rot[b, node]
            goal_rot = ra @ so3_exp(t * so3_log(np.swapaxes(ra, -1, -2) @ rb))
        held[side] = (frames, (1 - t) * place[a] + t * place[b], goal_rot)
    if not held:
        return q
    # One forward pass for both legs (a leg's joints move only its own foot), one step each.
    union = np.unique(np.concatenate([f for f, _, _ in held.values()]))
    poses = tree.forward(qpos[union, :3], quat_to_mat(qpos[union, 3:7]), q[union])
    for side, (frames, goal, goal_rot) in held.items():
        rows = np.searchsorted(union, frames)
        leg = leg_joints(robot, side)
        step = _gauss_newton(*_leg_residual(robot, side, poses.take(rows), goal, goal_rot))
        ok = np.abs(step).max(axis=1) <= HOLD_MAX_CHANGE
        q[frames[ok, None], leg] = np.clip(
            q[frames[ok, None], leg] + step[ok], robot.lower[leg], robot.upper[leg]
        )
    return q
