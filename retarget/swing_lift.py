"""Swing feet kept off the floor at the output rate (after resampling).

The solver keeps a swing foot its clearance high at the motion's frames; between them the
resampled joints may sweep a toe a few millimetres lower, and a foot that lands or takes off
may still be moving horizontally within a centimetre of the floor, where the simulation
check (:mod:`sim`) takes it for a standing foot that slides. :func:`lift_swing_feet` raises
such a foot with its own leg's joints, smoothly, without turning a joint faster or bringing
two geoms the self-clearance keeps apart closer than before.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial.transform import Rotation

from retarget.foot_targets import leg_joints
from retarget.kinematics import Poses
from retarget.robot_model import RobotModel
from retarget.selfcheck import pair_overlaps
from retarget.selfcollision import capsule_distances

SWING_TOLERANCE = 0.002
"""Swing feet may come this much (m) below their clearance at the output rate before being raised."""


SKIM_HEIGHT = 0.012
"""A foot that moves horizontally is kept at least this high (m): the simulation check counts
a foot within 1 cm of the floor as standing, and a standing foot must not slide."""
SKIM_SPEED = 0.1
"""Horizontal speed (m/s) of a foot's sole points above which it counts as moving."""


def lift_swing_feet(
    robot: RobotModel,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q: np.ndarray,
    clearance: dict[str, np.ndarray],
    fps: float,
) -> tuple[np.ndarray, float]:
    """Joint angles (T, nj) with moving feet kept off the floor at the output rate.

    The solver keeps a swing foot ``clearance`` high at the motion's frames; between them the
    resampled joints may swing the foot's lowest point (a toe sweeping past the floor) a few
    millimetres lower, and a foot that lands or takes off may still be moving horizontally
    while it is within a centimetre of the floor. Per output frame a foot needs its
    clearance (where that asks for more than standing height) and, wherever its slowest
    sole point below :data:`SKIM_HEIGHT` (in two frames) moves faster than :data:`SKIM_SPEED`,
    :data:`SKIM_HEIGHT`. Where it is more
    than :data:`SWING_TOLERANCE` below that, the rise is max-filtered and smoothed over
    ~0.2 s (never below the need) and the leg's joints translate the foot straight up by it,
    its orientation and horizontal place unchanged (one damped least-squares step per frame
    without the joints it would push past their limits, smoothed over time like the rise: a
    smooth correction adds no jerk), limits kept. Where the leg is short of a joint and that
    leaves the sole low, the foot turns instead, or gets no step (:func:`_turned_lift`).

    Args:
        robot: the robot; root_pos (T, 3), root_rot (T, 3, 3), q (T, nj) at ``fps``.
        clearance: per side, (T,) minimum height of the foot's collision points (m).

    Returns:
        (q, largest rise in m).
    """
    tree = robot.tree
    q_in = q
    q = q.copy()
    worst = 0.0
    r = max(1, int(round(0.05 * fps)))
    poses = tree.forward(root_pos, root_rot, q)
    t_len = len(q)
    for side in ("left", "right"):
        f = robot.feet[side]
        leg = leg_joints(robot, side)
        lo, hi = robot.lower[leg], robot.upper[leg]
        pts = f.world(poses)
        heights = pts[..., 2] - f.radius  # (T, P)
        h = heights.min(axis=1)
        # Like the simulation check, a foot moves when every sole point low in both frames
        # does: a point high above the floor that stays put (a heel strike's lifted toe) does
        # not make the landing heel slow.
        low = heights < SKIM_HEIGHT  # (T, P)
        step = np.linalg.norm(np.diff(pts[..., :2], axis=0), axis=2) * fps  # (T-1, P)
        step = np.where(low[1:] & low[:-1], step, np.inf).min(axis=1, initial=np.inf)
        step = np.where(np.isfinite(step), step, 0.0)
        moving = np.zeros(t_len, dtype=bool)
        moving[1:] |= step > SKIM_SPEED
        moving[:-1] |= step > SKIM_SPEED
        need = np.where(clearance[side] > 0.005, clearance[side], 0.0)
        need = np.where(moving, np.maximum(need, SKIM_HEIGHT), need)
        deficit = np.where(need > 0, need - h, 0.0)
        if deficit.max() <= SWING_TOLERANCE:
            continue
        rise = maximum_filter1d(np.maximum(deficit, 0.0), size=4 * r + 1, mode="nearest")
        rise = gaussian_filter1d(rise, sigma=r, mode="nearest", truncate=3.0)
        rise = np.maximum(rise, np.maximum(deficit, 0.0))
        worst = max(worst, float(rise.max()))
        idx = np.flatnonzero(rise > 1e-5)
        # Translate the foot straight up by the rise, its orientation and place unchanged:
        # the leg's joints solve [d position; d rotation] = [0, 0, rise; 0] (damped least squares).
        sub = poses.take(idx)
        node = np.array([f.node])
        jp = tree.point_jacobian(sub, node, sub.pos[:, node])[:, 0][..., 6 + leg]  # (F, 3, nl)
        jr = tree.rotation_jacobian(sub, node)[:, 0][..., 6 + leg]
        jac = np.concatenate([jp, jr], axis=1)  # (F, 6, nl)
        goal = np.zeros((len(idx), 6))
        goal[:, 2] = rise[idx]
        dq = np.zeros((t_len, len(leg)))
        dq[idx], short = _limited_step(jac, goal, q[np.ix_(idx, leg)], lo, hi)
        stuck = idx[short]
        if stuck.size:
            dq[stuck] = _turned_lift(
                robot,
                side,
                sub.take(np.flatnonzero(short)),
                root_pos[stuck],
                root_rot[stuck],
                q[stuck],
                dq[stuck],
                h[stuck],
                rise[stuck],
            )
        dq = gaussian_filter1d(dq, sigma=r / 2.0, axis=0, mode="nearest")
        q[:, leg] = np.clip(q[:, leg] + dq, lo, hi)
    if worst > 0.0:
        q = _guarded_lift(robot, root_pos, root_rot, q_in, q, poses, fps)
    return q, worst


LIFT_SELF_TOLERANCE = 0.002
"""How much closer (m) than before a lift may bring two of the robot's capsules that the solver
keeps apart, where that takes them inside their margin (pairs whose capsules are the geoms
themselves), or the others' real geoms deeper into each other than before. Checking the
capsules only for overlap (no margin) let Apollo's lifted knees snap past their velocity
limits in its turns."""


LIFT_SPEED = 2.0 * np.pi
"""rad/s: a lift may make a joint turn faster than before only up to this. Lifting a foot whose
knee is nearly straight bends the knee by the square root of the height: G1's right foot
lifted 2.4 cm as it slid in a stoop (corpus clip 000005) bent the knee 0.4 rad and straightened
it again at 23 rad/s, past its 20 rad/s limit."""


def _guarded_lift(
    robot: RobotModel,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q_in: np.ndarray,
    q: np.ndarray,
    poses: Poses,
    fps: float,
    passes: int = 4,
) -> np.ndarray:
    """The lift ``q - q_in`` (T, nj) at ``fps`` scaled down in the frames where it would turn a
    joint faster than before and than :data:`LIFT_SPEED`, or bring two geoms that the
    self-clearance keeps apart closer than before (:func:`_self_closer`): halved there,
    ``passes`` times at most, the scale smoothed over ~0.05 s. ``poses``: those of ``q_in``."""
    r = max(1, int(round(0.05 * fps)))
    moved = np.flatnonzero(np.abs(q - q_in).max(axis=1) > 0.0)  # the lifted frames
    speed_in = np.abs(np.diff(q_in, axis=0)) * fps
    closer = _self_closer(robot, root_pos, root_rot, poses, q_in, moved)
    scale = np.ones(len(q))
    out = q
    for _ in range(passes):
        speed = np.abs(np.diff(out, axis=0)) * fps
        faster = ((speed > speed_in) & (speed > LIFT_SPEED)).any(axis=1)  # (T - 1,)
        bad = np.zeros(len(q), dtype=bool)
        bad[:-1] |= faster
        bad[1:] |= faster
        if closer is not None:
            bad[moved] |= closer(out)
        if not bad.any():
            break
        scale[bad] *= 0.5
        scale = np.minimum(scale, gaussian_filter1d(scale, sigma=r / 2.0, mode="nearest"))
        out = q_in + scale[:, None] * (q - q_in)
    return out


def _self_closer(
    robot: RobotModel,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    poses: Poses,
    q_in: np.ndarray,
    moved: np.ndarray,
) -> Callable[[np.ndarray], np.ndarray] | None:
    """A test of lifted joint angles (T, nj): (F,) whether each of the ``moved`` frames brings
    two geoms that the self-clearance keeps apart closer than ``q_in`` (``poses``) did (the
    solver kept them apart, the lift knows nothing of them); None without a self-clearance.
    Pairs whose capsules are their geoms (capsules and spheres) and apart at rest count where
    their capsules come :data:`LIFT_SELF_TOLERANCE` closer inside their margin (Apollo's thigh
    lifted into the other in a turn); the others apart at rest (meshes, boxes: a capsule
    around them may overlap where the geoms do not) where their real geoms overlap that much
    deeper, measured by MuJoCo (:func:`retarget.selfcheck.pair_overlaps`: G1's hip lifted into
    its hand in a stoop, corpus clip 000005, 2.7 cm). Pairs whose enclosures overlap at rest
    (a trunk and a hip link) do not count: OP3's hip-pitch links press 2-4 mm further into its
    trunk mesh whenever a crouching walk lifts a foot, and its feet skimmed the floor."""
    sc = robot.self_clearance
    if sc is None or not moved.size:
        return None
    kind = robot.model.geom_type[sc.geom]
    own = (kind == int(mujoco.mjtGeom.mjGEOM_CAPSULE)) | (kind == int(mujoco.mjtGeom.mjGEOM_SPHERE))
    exact = own[sc.first] & own[sc.second] & (sc.margin >= 0.0)
    if sc.looseness is not None:
        exact &= sc.looseness == 0.0
    apart = (sc.margin if sc.safe_margin is None else sc.safe_margin) >= 0.0  # apart at rest
    capsules, geoms = sc.select_pairs(exact), sc.select_pairs(~exact & apart)
    quat = Rotation.from_matrix(root_rot[moved]).as_quat()[:, [3, 0, 1, 2]]
    root = np.concatenate([root_pos[moved], quat], axis=1)

    def real(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # overlaps of the other pairs' geoms
        frame, pair, depth = pair_overlaps(
            robot.model, robot.tree, np.concatenate([root, q[moved]], axis=1), geoms
        )
        return frame * geoms.num_pairs + pair, depth  # keys ascending

    before, _, _ = capsule_distances(poses.take(moved), capsules)
    allowed = np.minimum(before, capsules.margin) - LIFT_SELF_TOLERANCE  # (F, P)
    deepest = real(q_in) if geoms.num_pairs else None

    def closer(q: np.ndarray) -> np.ndarray:
        lifted = robot.tree.forward(root_pos[moved], root_rot[moved], q[moved])
        after, _, _ = capsule_distances(lifted, capsules)
        bad: np.ndarray = (after < allowed).any(axis=1)
        if deepest is not None:
            (was_key, was), (key, depth) = deepest, real(q)
            old = np.zeros(len(key))  # each overlap's depth before the lift (0: none)
            if len(key) and len(was_key):
                at = np.minimum(np.searchsorted(was_key, key), len(was_key) - 1)
                hit = was_key[at] == key
                old[hit] = was[at[hit]]
            bad[key[depth > old + LIFT_SELF_TOLERANCE] // geoms.num_pairs] = True
        return bad

    return closer


LIMITED_ROTATION_WEIGHT = 0.05
"""Metres per radian of a lifted foot's orientation change once a leg joint is at its limit."""
LIFT_SOLE_BAND = 0.005
"""Sole points up to this much (m) above where a lifted foot's lowest point must go are held
at that height (once a leg joint is at its limit): turning the foot must not lower them."""


def _limited_step(
    jac: np.ndarray,
    goal: np.ndarray,
    q: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    weights: np.ndarray | None = None,
    passes: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Damped least-squares joint step (F, n) towards ``goal`` (F, R) through ``jac`` (F, R, n)
    from ``q`` (F, n) within [lo, hi]: a joint the step would push past its limit (a hip pitch
    already at its stop) is taken out of that frame's solve and the others make up for it.
    Without row ``weights`` (F, R) the rows are a foot's position and rotation (R = 6), and
    short of a joint the rise comes first: the rotation gives way (0.05 m/rad). Returns the
    step and (F,) which frames were short of a joint."""
    free = np.ones(q.shape, dtype=bool)
    step: np.ndarray = np.zeros(q.shape)
    rows = np.ones(jac.shape[:2]) if weights is None else weights
    short = np.zeros(len(q), dtype=bool)
    for _ in range(passes):
        masked = jac * free[:, None, :] * rows[..., None]
        jt = np.swapaxes(masked, 1, 2)
        target = (goal * rows)[..., None]
        step = np.linalg.solve(jt @ masked + 1e-6 * np.eye(q.shape[1]), jt @ target)[..., 0]
        past = ((q + step < lo) | (q + step > hi)) & free
        if not past.any():
            break
        free &= ~past
        short |= past.any(axis=1)
        if weights is None:
            rows[short, 3:] = LIMITED_ROTATION_WEIGHT
    return step, short


def _turned_lift(
    robot: RobotModel,
    side: str,
    poses: Poses,
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    q: np.ndarray,
    dq: np.ndarray,
    height: np.ndarray,
    rise: np.ndarray,
) -> np.ndarray:
    """The lift of frames whose leg is short of a joint: (F, nl) ``dq`` (the step that raises the
    foot's origin), or where that leaves the lowest sole point (``height`` (F,) in ``poses``,
    those of ``q``) more than SWING_TOLERANCE below its level ``height + rise`` and more than
    SWING_TOLERANCE below SKIM_HEIGHT (where the simulation check would take the foot for a
    standing one) and a turn
    of the foot gets it there, that turn: the sole points below the level (and up to
    LIFT_SOLE_BAND above) rise to it, the lowest keeps its horizontal place and the foot's
    orientation gives way; where neither gets it higher, no step. A crouching walk's swing foot
    with its knee at the stop (Fourier GR1T2), pointing its toe down, lifts its toe by turning
    at the ankle. root_pos (F, 3), root_rot (F, 3, 3), q (F, nj)."""
    tree, f, leg = robot.tree, robot.feet[side], leg_joints(robot, side)
    lo, hi = robot.lower[leg], robot.upper[leg]

    def reached(step: np.ndarray, rows: np.ndarray) -> np.ndarray:
        moved = q[rows].copy()
        moved[:, leg] = np.clip(moved[:, leg] + step, lo, hi)
        return f.lowest(tree.forward(root_pos[rows], root_rot[rows], moved))[0]

    level = height + rise
    before = reached(dq, np.arange(len(q)))
    enough = np.minimum(level, SKIM_HEIGHT) - SWING_TOLERANCE
    fail = np.flatnonzero(before < enough)
    if not fail.size:
        return dq
    sub = poses.take(fail)
    node = np.array([f.node])
    sole = f.world(sub)  # (F', P, 3)
    need = level[fail, None] - (sole[..., 2] - f.radius)  # (F', P) rise of each point to the level
    jz = tree.point_jacobian(sub, np.full(sole.shape[1], f.node), sole, rows=(2,))[:, :, 0][..., 6 + leg]
    low = f.lowest(sub)[1][:, None, :]
    jxy = tree.point_jacobian(sub, node, low, rows=(0, 1))[:, 0][..., 6 + leg]
    jr = tree.rotation_jacobian(sub, node)[:, 0][..., 6 + leg]
    jac = np.concatenate([jxy, jz, jr], axis=1)  # (F', 2 + P + 3, nl)
    goal = np.concatenate([np.zeros((len(fail), 2)), need, np.zeros((len(fail), 3))], axis=1)
    weights = np.concatenate(
        [
            np.ones((len(fail), 2)),
            (need > -LIFT_SOLE_BAND).astype(float),
            np.full((len(fail), 3), LIMITED_ROTATION_WEIGHT),
        ],
        axis=1,
    )
    turn, _ = _limited_step(jac, goal, q[np.ix_(fail, leg)], lo, hi, weights)
    out = dq.copy()
    turned = reached(turn, fail)
    higher = (turned > before[fail]) & (turned >= enough[fail])
    out[fail[higher]] = turn[higher]
    # Neither raising the lowest point, the foot stays as it was (the origin's rise, all the leg
    # could give, swung G1's flat foot 17 cm with its knee at the stop).
    still = np.maximum(turned, before[fail]) <= height[fail]
    out[fail[still]] = 0.0
    return out
