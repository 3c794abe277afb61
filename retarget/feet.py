"""Stance feet pinned in place after the solve (at the solver's frame rate).

The whole-sequence solve holds stance feet with a strong but soft lock, so a planted foot
may still wander by a few millimetres when the rest of the body pulls. Here every stance
frame moves that leg's own joints (those between the trunk and that foot) so that the foot
reaches its locked target: damped Gauss-Newton on the position of the foot's point that
should stay put (:func:`pin_points`: the ankle keypoint of a flat foot, the heel or toe pivot
of a rolling one) and on the foot's orientation (at 0.05 m/rad, for legs with six or more
joints; a five-joint leg such as H1's keeps the solver's foot orientation), all frames at
once; a step that does not lower a frame's error is undone, and a frame whose correction
would turn a joint by more than PIN_MAX_CHANGE keeps the solver's pose (the lock is out of
the leg's reach there). The correction is exact inside a run of pinned frames, faded out
around each stance with the lock weight, and smoothed over time (Gaussian, sigma = 1 frame)
where it starts, stops or is refused, so that pinning adds little jerk.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d, minimum_filter1d

from retarget.foot_targets import FULL_LEG_JOINTS, foot_pivots, leg_joints
from retarget.kinematics import Poses, quat_to_mat, so3_exp, so3_log
from retarget.robot_model import RobotModel
from retarget.targets import Targets

PIN_L_ROT = 0.05
"""Metres per radian of foot orientation error when pinning (position first)."""
PIN_MAX_CHANGE = 0.2
"""Largest joint change (rad) pinning may make in a frame; larger ones are not applied there."""
STEP_DAMPING = 1e-5
"""Damping (m^2/rad^2) of the Gauss-Newton steps."""
PIN_DAMPING = 3e-3
"""Damping (m^2/rad^2) of the pinning's and holding's steps for legs of FULL_LEG_JOINTS or more
joints, whose corrections are applied exactly (unsmoothed) within a stance: a stretched leg is
near-singular, and steps damped by STEP_DAMPING turned its joints by up to 0.05 rad for
millimetres, differently each frame (joint jerk). A five-joint leg's position-only pin keeps
STEP_DAMPING: damped more, it fell short (a 7.9 mm slide in a frame of H1's corpus clip
000004, 0.24 m/s, past ``controlmm validate``'s limit)."""
EXACT_MARGIN = 2
"""Frames a pinned frame must be from a frame pinned less (unpinned, or its correction
refused) for its correction to be applied exactly rather than smoothed."""
PIVOT_RISE = 0.005
"""Metres by which one end of a locked foot stands above the other, in its target or in the
solve, for the foot to be pinned wholly by its lower end's pivot (:func:`pin_points`); level
feet are pinned by their ankle keypoint, and the point slides between the two in proportion.
A point that jumps from one frame to the next (1 mm was once the switch) makes the foot
jump by the orientation error times their distance: ergoCub's left foot slid 7.2 mm in a
frame of corpus clip 000000, DARwIn-OP's right 6.7 mm in 000004 (0.2 m/s, past ``controlmm
validate``'s limit)."""


def pin_points(
    robot: RobotModel,
    targets: Targets,
    side: str,
    frames: np.ndarray,
    poses: Poses,
) -> tuple[np.ndarray, np.ndarray]:
    """The point of the ``side`` foot that pinning puts in place at ``frames`` (F,) of the
    solve (``poses``: its poses there): (F, 3) in the foot's node frame, and (F, 3) its place
    (m, world) in the targets.

    A level foot is pinned by its ankle keypoint. A foot rolling over its toe or heel, in the
    targets or in the solve (whichever lifts one end of :func:`retarget.foot_targets.foot_pivots`
    more above the other: a leg that cannot reach lifts its heel early), is pinned by the
    pivot it rolls on, wholly from PIVOT_RISE on and on a point between the ankle keypoint
    and that pivot below it. The orientation is pinned softly (PIN_L_ROT), so its error shows
    least at the point pinned: that point should be the one on the floor. Legs of fewer than
    FULL_LEG_JOINTS joints, whose foot orientation is not pinned, keep the ankle keypoint."""
    k = robot.keypoint_index(f"{side}_ankle")
    ankle = np.tile(robot.offsets[k], (len(frames), 1))
    goal = targets.kp_pos[frames, k]
    if k not in targets.ori_kp or len(leg_joints(robot, side)) < FULL_LEG_JOINTS:
        return ankle, goal
    rot = targets.ori_rot[frames, list(targets.ori_kp).index(k)]  # (F, 3, 3) the node's target
    heel, toe = foot_pivots(robot, side)
    node = np.array([int(robot.nodes[k])])
    solved = robot.tree.points(poses, np.repeat(node, 2), np.stack([heel, toe]))[..., 2]  # (F, 2)
    wanted = np.einsum("fij,pj->fpi", rot, np.stack([heel, toe]) - robot.offsets[k])[..., 2]
    rise = np.stack([wanted[:, 0] - wanted[:, 1], solved[:, 0] - solved[:, 1]])  # > 0: heel up
    rise = rise[np.abs(rise).argmax(axis=0), np.arange(len(frames))]
    share = np.clip(rise / PIVOT_RISE, -1.0, 1.0)[:, None]  # 1: the toe, -1: the heel, 0: the ankle
    point = ankle + np.maximum(share, 0.0) * (toe - ankle) + np.maximum(-share, 0.0) * (heel - ankle)
    return point, goal + np.einsum("fij,fj->fi", rot, point - robot.offsets[k])


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
        full = len(leg) >= FULL_LEG_JOINTS  # orientation pinned, correction exact, steps damped
        o = list(targets.ori_kp).index(k) if (k in targets.ori_kp and full) else None
        goal_rot = targets.ori_rot[frames, o] if o is not None else None
        start = q[np.ix_(frames, leg)].copy()
        solved = robot.tree.forward(root_pos[frames], root_rot[frames], q[frames])
        point, goal = pin_points(robot, targets, side, frames, solved)
        best = _pin_leg(
            robot,
            side,
            root_pos[frames],
            root_rot[frames],
            q[frames],
            solved,
            point,
            goal,
            goal_rot,
            iterations,
            PIN_DAMPING if full else STEP_DAMPING,
        )
        # Correction over all frames: in stance, faded by the lock weight around it.
        # A frame whose leg would have to swing far (an unreachable lock: another IK branch)
        # keeps the solver's pose: pinning fixes millimetres, it does not re-pose a leg.
        delta = np.zeros((len(q), len(leg)))
        change = best - start
        taken = np.abs(change).max(axis=1) <= PIN_MAX_CHANGE
        delta[frames] = np.where(taken[:, None], change, 0.0)
        exact = np.zeros(len(q))
        if full:  # a five-joint leg's foot turns with its position-only correction: smoothed
            exact[frames[taken]] = 1.0
        near = np.flatnonzero((lock > 0) & ~np.isin(np.arange(len(q)), frames))
        if len(near):
            nearest = frames[np.abs(near[:, None] - frames[None, :]).argmin(axis=1)]
            delta[near] = lock[near, None] * delta[nearest]
        # Inside a run of pinned frames the correction is exact; where it starts, stops or is
        # refused, smoothed: a correction that jumps would add jerk.
        inner = minimum_filter1d(exact, 2 * EXACT_MARGIN + 1, mode="constant", cval=0.0)
        inner = gaussian_filter1d(inner, sigma=1.0, mode="nearest")[:, None]
        delta = inner * delta + (1 - inner) * gaussian_filter1d(delta, sigma=1.0, axis=0, mode="nearest")
        q[:, leg] = np.clip(q[:, leg] + delta, robot.lower[leg], robot.upper[leg])
    return q


def _pin_leg(
    robot: RobotModel,
    side: str,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q: np.ndarray,
    poses: Poses,
    point: np.ndarray,
    goal: np.ndarray,
    goal_rot: np.ndarray | None,
    iterations: int,
    damping: float = STEP_DAMPING,
) -> np.ndarray:
    """One leg's joints (F, nl) that bring the foot's ``point`` (F, 3, node frame) to ``goal``
    (F, 3) (and the foot to ``goal_rot`` (F, 3, 3) at PIN_L_ROT m/rad when given) for F
    frames of root_pos (F, 3), root_rot (F, 3, 3), q (F, nj) (``poses``: theirs): damped
    Gauss-Newton, a step that does not lower a frame's error undone, limits kept."""
    leg = leg_joints(robot, side)
    lo, hi = robot.lower[leg], robot.upper[leg]
    cur = q[:, leg].copy()
    best = cur.copy()
    best_cost = np.full(len(q), np.inf)
    base = q.copy()
    for it in range(iterations + 1):
        if it:
            base[:, leg] = cur
            poses = robot.tree.forward(root_pos, root_rot, base)
        res, jac = _leg_residual(robot, side, poses, point, goal, goal_rot)
        cost = np.sum(res * res, axis=1)
        better = cost < best_cost
        best[better], best_cost[better] = cur[better], cost[better]
        if it == iterations:
            break
        cur = np.clip(np.where(better[:, None], cur, best) + _gauss_newton(res, jac, damping), lo, hi)
    return best


def _leg_residual(
    robot: RobotModel,
    side: str,
    poses: Poses,
    point: np.ndarray,
    goal: np.ndarray,
    goal_rot: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The residual (F, 3 or 6: position, then orientation at PIN_L_ROT m/rad) of the foot's
    ``point`` (F, 3, node frame) to ``goal`` / ``goal_rot`` and its Jacobian (F, 3 or 6, nl) in
    the leg's joints."""
    tree = robot.tree
    node = np.array([int(robot.nodes[robot.keypoint_index(f"{side}_ankle")])])
    leg = leg_joints(robot, side)
    pt = np.einsum("fij,fj->fi", poses.rot[:, node[0]], point) + poses.pos[:, node[0]]
    res = pt - goal
    jac = tree.point_jacobian(poses, node, pt[:, None])[:, 0][..., 6 + leg]  # (F, 3, nl)
    if goal_rot is not None:
        err = so3_log(poses.rot[:, node[0]] @ np.swapaxes(goal_rot, -1, -2)) * PIN_L_ROT
        res = np.concatenate([res, err], axis=1)
        jr = tree.rotation_jacobian(poses, node)[:, 0][..., 6 + leg] * PIN_L_ROT
        jac = np.concatenate([jac, jr], axis=1)
    return res, jac


def _gauss_newton(res: np.ndarray, jac: np.ndarray, damping: float = STEP_DAMPING) -> np.ndarray:
    """Damped Gauss-Newton steps (F, n) for residuals (F, m) with Jacobians (F, m, n)."""
    jt = np.swapaxes(jac, 1, 2)
    return np.linalg.solve(jt @ jac + damping * np.eye(jac.shape[2]), -(jt @ res[..., None]))[..., 0]


HOLD_STILL = 0.002
HOLD_TURN = 0.02
"""A pinned foot is held between two solver frames where a point of it (its ankle keypoint,
heel or toe pivot) moves less than HOLD_STILL (m) there, and, held by its ankle keypoint,
turns less than HOLD_TURN (rad): a planted foot, or one rolling over its heel or toe."""
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
    lock 1), the point of it that moves least between them (its ankle keypoint if planted,
    its heel or toe pivot if rolling over it; legs of fewer than six joints: the ankle
    keypoint) goes back onto the line between its two places, and the foot onto the rotation
    between their orientations (legs of six or more joints): one Gauss-Newton step of the
    leg's joints, kept where no joint turns more than HOLD_MAX_CHANGE.

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
    held: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]] = {}
    for side in ("left", "right"):
        pinned = targets.stance[side] & (targets.lock[side] >= 1.0)
        frames = np.flatnonzero(between & pinned[i0] & pinned[i1])
        k = robot.keypoint_index(f"{side}_ankle")
        node = int(robot.nodes[k])
        a, b = i0[frames], i1[frames]
        # The foot's point that stays put between the two frames: the ankle keypoint of a
        # planted foot, the heel or toe pivot of one rolling over it.
        full = len(leg_joints(robot, side)) >= FULL_LEG_JOINTS
        points = np.stack([robot.offsets[k], *foot_pivots(robot, side)] if full else [robot.offsets[k]])
        place = tree.points(src, np.full(len(points), node), points)  # (T, P, 3)
        moved = np.linalg.norm(place[b] - place[a], axis=-1)  # (F, P)
        pick = moved.argmin(axis=1)
        turn = np.linalg.norm(so3_log(np.swapaxes(src.rot[a, node], -1, -2) @ src.rot[b, node]), axis=-1)
        rows = np.arange(len(frames))
        still = (moved[rows, pick] < HOLD_STILL) & ((turn < HOLD_TURN) | (pick > 0))
        frames, a, b, pick = frames[still], a[still], b[still], pick[still]
        if len(frames) == 0:
            continue
        t = w[frames, None]
        goal_rot = None
        if full:
            ra, rb = src.rot[a, node], src.rot[b, node]
            goal_rot = ra @ so3_exp(t * so3_log(np.swapaxes(ra, -1, -2) @ rb))
        goal = (1 - t) * place[a, pick] + t * place[b, pick]
        held[side] = (frames, points[pick], goal, goal_rot)
    if not held:
        return q
    # One forward pass for both legs (a leg's joints move only its own foot), one step each.
    union = np.unique(np.concatenate([f for f, _, _, _ in held.values()]))
    poses = tree.forward(qpos[union, :3], quat_to_mat(qpos[union, 3:7]), q[union])
    for side, (frames, point, goal, goal_rot) in held.items():
        rows = np.searchsorted(union, frames)
        leg = leg_joints(robot, side)
        residual = _leg_residual(robot, side, poses.take(rows), point, goal, goal_rot)
        step = _gauss_newton(*residual, PIN_DAMPING if len(leg) >= FULL_LEG_JOINTS else STEP_DAMPING)
        ok = np.abs(step).max(axis=1) <= HOLD_MAX_CHANGE
        q[frames[ok, None], leg] = np.clip(
            q[frames[ok, None], leg] + step[ok], robot.lower[leg], robot.upper[leg]
        )
    return q
