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
FULL_LEG_JOINTS = 6
"""Joints a leg needs of its own (:func:`leg_joints`) to hold a foot's place and turn at once:
with fewer, a planted foot is held by its place alone (:mod:`retarget.feet`) and gets no
harder roll lock (:func:`feet_targets`)."""
FOOT_GAP = 0.02
"""Metres kept between the two feet's footprints (each grown by half of it on every side)."""
KNEE_TWIST_DEG = 10.0
"""Largest angle (degrees) between a foot's heading and the human's knee direction that the
foot keeps (:func:`knee_turn`)."""
KNEE_TURN_MOST_DEG = 8.0
"""The most (degrees) a foot turns towards the knee (:func:`knee_turn`): a landing foot turned
further than the human's toes point twists on the floor as it lands."""
TURN_SMOOTH_SECONDS = 0.1
"""Gaussian sigma (s) with which a foot's knee turn passes from one contact run's to the next."""
KNEE_BEND_FULL = 0.16
"""Distance of the human's knee from its hip-ankle line, as a fraction of the leg's length,
from which the knee's direction counts fully (less bent: proportionally less)."""
HELD_PITCH_SECONDS = 0.5
"""A human foot down but not flat for longer than this (s) holds its pitch (kneeling on the
toes, a tiptoe stand), and a flat contact foot (``roll`` 0) rolls with all of it
(:func:`roll_share`); heel strikes and toe-offs are shorter (at most 0.25 s in the corpus's
walks and runs)."""


def leg_joints(robot: RobotModel, side: str) -> np.ndarray:
    """Indices (into q) of the joints between the trunk and one foot that move that foot
    alone: a joint the MJCF couples to another (NAO's hip yaw-pitch, one motor for both hips)
    is left to the solver, which keeps the coupling (:mod:`retarget.costs.coupling`)."""
    other = {"left": "right", "right": "left"}[side]
    anc = robot.tree.ancestor
    leg = np.flatnonzero(anc[int(robot.feet[side].node)] & ~anc[int(robot.feet[other].node)])
    if robot.couplings is not None:
        leg = np.setdiff1d(leg, robot.couplings.joints)
    return leg


def knee_direction(world: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Heading (rad, about +Z) of the human's knee as seen from its hip-ankle line, and how
    bent the knee is: its distance from that line over the leg's length (thigh + shank), (T,)
    each (a straight leg: 0, and its heading is meaningless)."""
    hip, knee, ankle = (world[:, JOINT_INDEX[f"{side}_{j}"]] for j in ("hip", "knee", "ankle"))
    axis = ankle - hip
    axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-9)
    out = knee - hip
    out = out - np.sum(out * axis, axis=1, keepdims=True) * axis
    leg = np.linalg.norm(knee - hip, axis=1) + np.linalg.norm(ankle - knee, axis=1)
    return np.arctan2(out[:, 1], out[:, 0]), np.linalg.norm(out, axis=1) / np.maximum(leg, 1e-9)


def knee_turn(world: np.ndarray, side: str) -> np.ndarray:
    """(T,) how far (rad, about +Z) the robot's foot turns from the human's toe heading
    towards the human's knee.

    Where the human's toes point more than KNEE_TWIST_DEG away from its bent knee (toes turned
    out in a squat), the robot's foot cannot follow both: a human shank twists under the knee
    (tibial torsion, the ankle's own turn), a robot's does not (its knee axis is its ankle's
    pitch axis), so a robot foot turned with the toes takes the knee out with it. The foot
    turns towards the knee's direction (:func:`knee_direction`) by the twist beyond
    KNEE_TWIST_DEG, at most KNEE_TURN_MOST_DEG, in proportion to how bent the knee is (fully
    from KNEE_BEND_FULL); 0 elsewhere.
    """
    toe = foot_heading_pitch(world, side)[0]
    knee, bend = knee_direction(world, side)
    twist = np.angle(np.exp(1j * (knee - toe)))  # wrapped to (-pi, pi]
    limit, most = np.radians(KNEE_TWIST_DEG), np.radians(KNEE_TURN_MOST_DEG)
    excess = np.clip(twist - np.clip(twist, -limit, limit), -most, most)
    return np.clip(bend / KNEE_BEND_FULL, 0.0, 1.0) * excess


def foot_heading_pitch(world: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Heading (yaw about +Z) and elevation (rad) of the human's ankle -> toe vector, (T,) each."""
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


def _roll_rise(rest_rot: np.ndarray, theta: np.ndarray, c_heel: np.ndarray, c_toe: np.ndarray) -> np.ndarray:
    """(T,) how high (m) a foot pitched by ``theta`` (T,) rad (> 0: toe down) about the pivot
    on the floor (toe or heel, node frame (3,)) lifts its node above the flat foot's."""
    pivot = np.where((theta > 0)[:, None], c_toe, c_heel)
    flat = pivot @ rest_rot.T
    rolled = np.einsum("tij,tj->ti", rot_y(theta) @ rest_rot, pivot)
    return flat[:, 2] - rolled[:, 2]


def footprint(robot: RobotModel, side: str) -> np.ndarray:
    """(x_min, x_max, y_min, y_max) of a flat foot's collision geometry around its ankle keypoint (m;
    x forward, y left)."""
    f = robot.feet[side]
    rot = robot.foot_flat_rot[side]
    rel = (f.points - robot.offsets[robot.keypoint_index(f"{side}_ankle")]) @ rot.T
    r = f.radius
    return np.array(
        [(rel[:, 0] - r).min(), (rel[:, 0] + r).max(), (rel[:, 1] - r).min(), (rel[:, 1] + r).max()]
    )


def _heading_axes(pelvis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, heading): the horizontal forward and left axes (T, 3) of the pelvis frames
    (T, 3, 3) and their heading (T,) about +Z."""
    x = pelvis[:, :, 0].copy()
    x[:, 2] = 0.0
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-9)
    y = np.stack([-x[:, 1], x[:, 0], np.zeros(len(x))], axis=1)
    return x, y, np.arctan2(x[:, 1], x[:, 0])


def _footprint_corners(robot: RobotModel, side: str, turn: np.ndarray) -> np.ndarray:
    """(T, 4, 2) corners of a foot's footprint grown by FOOT_GAP / 2 on every side, turned by
    ``turn`` (T,) rad about +Z, around its ankle keypoint (m; x forward, y left)."""
    box = footprint(robot, side) + np.array([-1.0, 1.0, -1.0, 1.0]) * FOOT_GAP / 2
    corners = np.array([[box[i], box[j]] for i in (0, 1) for j in (2, 3)])  # (4, 2)
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    return np.stack([c * corners[:, 0] - s * corners[:, 1], s * corners[:, 0] + c * corners[:, 1]], axis=-1)


def sideways_overlap(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shifts along y of the convex polygon ``left`` (T, N, 2) at which it meets ``right``
    (T, M, 2): the interval (lo, hi) (T,) each, (inf, -inf) where no shift along y makes them
    meet. They overlap where lo < 0 < hi.

    A shift d meets where d * y lies in the Minkowski difference right - left, the convex hull
    of every corner difference; its section by the y axis is spanned by where the segments
    between pairs of those points cross x = 0 (every hull edge is one of them, every such
    segment lies inside the hull).
    """
    diff = (right[:, :, None] - left[:, None, :]).reshape(len(left), -1, 2)
    i, j = np.triu_indices(diff.shape[1], 1)
    a, b = diff[:, i], diff[:, j]
    cross = (a[..., 0] <= 0) != (b[..., 0] <= 0)
    run = np.where(cross, b[..., 0] - a[..., 0], 1.0)
    y = a[..., 1] - a[..., 0] * (b[..., 1] - a[..., 1]) / run
    return np.where(cross, y, np.inf).min(axis=1), np.where(cross, y, -np.inf).max(axis=1)


def feet_shortfall(
    robot: RobotModel, kp_pos: np.ndarray, world: np.ndarray, pelvis: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """How far (m, (T,), signed) the left ankle target must move relative to the right one along
    the pelvis heading's left axis (T, 3) for the robot's feet not to overlap.

    Each foot's footprint (:func:`footprint`, grown by FOOT_GAP / 2 on every side) is turned
    by the robot foot's heading (the human's toes' turned by :func:`knee_turn`, per frame;
    ``world``: the scaled human (T, 22, 3)). Where the two overlap, the shortest move that
    parts them: the left foot to the left (> 0) or, feet crossed, to the right (< 0); 0
    elsewhere.
    """
    kl, kr = robot.keypoint_index("left_ankle"), robot.keypoint_index("right_ankle")
    x, y, pelvis_heading = _heading_axes(pelvis)
    d = kp_pos[:, kl] - kp_pos[:, kr]
    heading = {
        side: foot_heading_pitch(world, side)[0] + knee_turn(world, side) - pelvis_heading
        for side in ("left", "right")
    }
    left = _footprint_corners(robot, "left", heading["left"])
    left = left + np.stack([np.sum(d * x, axis=1), np.sum(d * y, axis=1)], axis=-1)[:, None]
    right = _footprint_corners(robot, "right", heading["right"])
    lo, hi = sideways_overlap(left, right)
    overlap = (lo < 0) & (hi > 0)
    return np.where(overlap, np.where(hi <= -lo, hi, lo), 0.0), y


def _move_foot(robot: RobotModel, kp_pos: np.ndarray, side: str, delta: np.ndarray) -> None:
    for joint in (f"{side}_ankle", f"{side}_foot"):
        if robot.has_keypoint(joint):
            kp_pos[:, robot.keypoint_index(joint)] += delta


def foot_keypoints(robot: RobotModel, side: str) -> list[int]:
    """Indices of the ``side`` foot's keypoints (its ankle and, on the same body, its toe):
    the ones a stance locks."""
    foot_node = robot.nodes[robot.keypoint_index(f"{side}_ankle")]
    return [
        k
        for k in range(len(robot.joints))
        if robot.nodes[k] == foot_node and robot.keypoint_names[k] in (f"{side}_ankle", f"{side}_foot")
    ]


def space_feet(robot: RobotModel, kp_pos: np.ndarray, world: np.ndarray, pelvis: np.ndarray) -> None:
    """Push the feet targets apart sideways where the robot's feet would overlap (in place).

    The limb targets follow the scaled human's feet (:func:`retarget.targets.fit_limbs_to_human`),
    and a robot's feet may be wider or longer than the scaled human's. Per frame, each side
    moves half the :func:`feet_shortfall` along the pelvis heading's left axis, its toe with it.
    """
    if not all(robot.has_keypoint(n) for n in ("left_ankle", "right_ankle")):
        return
    short, y = feet_shortfall(robot, kp_pos, world, pelvis)
    for side, sign in (("left", 0.5), ("right", -0.5)):
        _move_foot(robot, kp_pos, side, sign * short[:, None] * y)


def separate_locks(
    robot: RobotModel,
    kp_pos: np.ndarray,
    world: np.ndarray,
    pelvis: np.ndarray,
    runs: dict[str, np.ndarray],
    alpha_xy: dict[str, np.ndarray],
    passes: int = 2,
) -> None:
    """Move whole foot locks apart where the two locked feet would overlap, and a foot passing
    a locked one around it (in place).

    A lock is one place per contact run, the mean of the run's targets, so two locks may
    overlap although every frame's targets were spaced (:func:`space_feet`). Each run of
    each foot (``runs[side]``: (T,) run index per frame, -1 outside) moves by one constant
    vector, half the largest :func:`feet_shortfall` over its frames where the other foot is
    locked too, along their mean left axis, weighted by the run's horizontal lock weight
    ``alpha_xy[side]`` (T,): the locked foot stays still. Then, where only the other foot is
    locked, the unlocked one takes the whole remaining shortfall: a planted foot keeps the
    human's place and the swinging foot goes around it.
    """
    if not all(robot.has_keypoint(n) for n in ("left_ankle", "right_ankle")):
        return
    sides = (("left", "right", 0.5), ("right", "left", -0.5))
    for _ in range(passes):
        short, y = feet_shortfall(robot, kp_pos, world, pelvis)
        if not np.any(np.abs(short) > 1e-6):
            return
        for side, other, sign in sides:
            owner = runs[side]
            for run in np.unique(owner[owner >= 0]):
                frames = owner == run
                need = frames & (np.abs(short) > 1e-6) & (alpha_xy[other] > 0)
                if not need.any():
                    continue
                axis = y[need].mean(axis=0)
                axis /= max(float(np.linalg.norm(axis)), 1e-9)
                worst = short[need][np.argmax(np.abs(short[need]))]
                shift = sign * float(worst) * axis
                _move_foot(robot, kp_pos, side, np.where(frames, alpha_xy[side], 0.0)[:, None] * shift)
    short, y = feet_shortfall(robot, kp_pos, world, pelvis)
    for side, other, sign in sides:
        passing = (1.0 - alpha_xy[side]) * (alpha_xy[other] > 0)
        _move_foot(robot, kp_pos, side, (2 * sign * passing * short)[:, None] * y)


def _run_turn(turn: np.ndarray, runs: list[tuple[int, int]], owner: np.ndarray, fps: float) -> np.ndarray:
    """The foot's :func:`knee_turn` (T,) held at its mean over each contact run for the frames
    the run owns (``owner``: (T,) nearest run), then smoothed over TURN_SMOOTH_SECONDS: a
    foot lands already turned as it stands and does not twist while it bends its knee (with
    no contact run at all, the per-frame turn, smoothed)."""
    if runs:
        turn = np.array([turn[s:e].mean() for s, e in runs])[owner]
    if len(turn) > 2:
        turn = gaussian_filter1d(turn, TURN_SMOOTH_SECONDS * fps, mode="nearest")
    return turn


def roll_share(contact: np.ndarray, flat: np.ndarray, fps: float, roll: float) -> np.ndarray:
    """(T,) share of the human foot's pitch with which the robot's contact foot rolls: ``roll``
    (``SolverConfig.foot_roll``) over the frames of a heel strike or toe-off (``contact`` but not
    ``flat``, both (T,) bool); with ``roll`` 0 (flat contact feet), 1 over a pitch held longer
    than HELD_PITCH_SECONDS: a foot kept flat under a kneeling human's toes held the knee off
    the floor (G1 on corpus 000018: 8.23 cm from the human, 2.57 with the rule). A half-rolling
    foot keeps its share there too: rolling fully took H1's kneel out of its ankle motors'
    range (a fallback of ``controlmm retarget`` that passed before)."""
    share = np.full(len(contact), float(roll))
    if roll == 0:
        for s, e in true_runs(contact & ~flat):
            if e - s > HELD_PITCH_SECONDS * fps:
                share[s:e] = 1.0
    return share


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
    roll: float = 1.0,
    roll_gain: float = 1.0,
    lift_share: float = 0.0,
) -> np.ndarray:
    """Lift swing-foot targets to the robot's stance height; in contact, a rigid rolling foot.

    Each contact run gets one place and heading. Within it the foot is flat while the human
    foot is flat, and otherwise pitches with the human foot about its heel pivot (toe up: a
    heel strike) or its toe pivot (heel up: a toe-off, tiptoes), the pivot fixed on the floor
    (:func:`foot_pivots`): the robot rolls over its sole instead of hovering or sliding.
    ``roll`` (``SolverConfig.foot_roll``) scales that pitch (0: the foot stays flat while the
    human's is down), and ``lift_share`` (``SolverConfig.foot_lift``) raises such a foot straight up
    by that share of the height the rest of the pitch would have raised its node. The lock
    weight is LOCK_GAIN times the foot targets' own, and ``roll_gain``
    (``SolverConfig.roll_lock_gain``) times more where the human's foot is down but not flat:
    a rolling foot keeps its pivot where it is. A leg of fewer than six joints of its own
    (H1's, without an ankle roll) cannot hold a foot's place and turn at once, and gets no
    such gain: a harder lock took the solve's room to keep H1-with-hands' links apart
    (38 self-collision frames on the real clip). Returns (T,) the contact run each frame's
    lock belongs to (-1 where the foot is not locked).
    """
    ka = robot.keypoint_index(f"{side}_ankle")
    same_node = foot_keypoints(robot, side)
    rest_rot = robot.foot_flat_rot[side]  # the foot flat on the floor, facing +X
    flat_height = robot.foot_flat_height[side]  # its node's height then
    heading, elevation = foot_heading_pitch(world, side)
    runs = true_runs(contact)
    frames = np.arange(len(world))
    owner = np.zeros(len(world), dtype=int)
    if runs:
        starts = np.array([s for s, _ in runs])
        ends = np.array([e - 1 for _, e in runs])
        gap = np.maximum(starts[None, :] - frames[:, None], 0) + np.maximum(
            frames[:, None] - ends[None, :], 0
        )
        owner = np.argmin(gap, axis=1)  # every frame belongs to its nearest contact run
    heading = heading + _run_turn(knee_turn(world, side), runs, owner, fps)
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
    owner_out = np.full(len(world), -1)
    if runs:
        # In contact: flat when both heel and toe are down, else rolling on the pivot that
        # the human's pitch puts on the floor (never rolling onto the lifted end).
        theta = np.where(heel & toe, 0.0, pitch)
        theta = np.where(toe & ~heel, np.maximum(theta, 0.0), theta)
        theta = np.where(heel & ~toe, np.minimum(theta, 0.0), theta)
        # The flags switch within a frame; the pitch must not: smooth it over ~0.1 s (the
        # pivot follows its sign, and both pivots are on the floor when it is 0). The swing's
        # pitch that the smoothing carries into a contact's first and last frames is scaled
        # like the contact's own, so that ``roll`` 0 keeps the foot flat for the whole contact.
        held = np.where(contact, theta, 0.0)
        swing = np.where(contact, 0.0, pitch)
        share = roll_share(contact, heel & toe, fps, roll)
        if len(theta) > 2:
            held = gaussian_filter1d(held, PITCH_SMOOTH_SECONDS * fps, mode="nearest")
            swing = gaussian_filter1d(swing, PITCH_SMOOTH_SECONDS * fps, mode="nearest")
            if roll == 0:
                share = gaussian_filter1d(share, PITCH_SMOOTH_SECONDS * fps, mode="nearest")
        theta = share * held + np.where(contact, share, 1.0) * swing
        c_heel, c_toe = foot_pivots(robot, side)
        pivot = np.where((theta > 0)[:, None], c_toe, c_heel)  # (T, 3) node frame
        # A foot rolling less than the human's (``roll`` < 1) rises by ``lift_share`` times what the
        # rest of the roll would have lifted its node, straight up (0 where ``roll`` is 1).
        rise = np.zeros(len(world))
        if lift_share > 0 and roll < 1:  # (0 where the share is 1: a held pitch)
            full = _roll_rise(rest_rot, held + swing, c_heel, c_toe)
            rise = lift_share * (full - _roll_rise(rest_rot, theta, c_heel, c_toe))
        height = flat_height + STANCE_CLEARANCE
        for i, (s, e) in enumerate(runs):
            sel = (owner == i) & (alpha_xy > 0)
            owner_out[sel] = i
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
            lock_node[sel, 2] += rise[sel]
    a = np.stack([alpha_xy, alpha_xy, alpha], axis=1)
    roll_gain = roll_gain if len(leg_joints(robot, side)) >= FULL_LEG_JOINTS else 1.0
    gain = LOCK_GAIN * np.where(contact & ~(heel & toe), roll_gain, 1.0)  # (T,)
    for k in same_node:
        locked = lock_node + np.einsum("tij,j->ti", lock_rot, robot.offsets[k])
        kp_pos[:, k] = a * locked + (1 - a) * kp_pos[:, k]
        kp_weight[:, k] *= 1 + alpha * (gain - 1)
    if ka in ori_kp:
        o = ori_kp.index(ka)
        delta = so3_log(np.swapaxes(swing_rot, -1, -2) @ lock_rot)
        ori_rot[:, o] = swing_rot @ so3_exp(delta * alpha[:, None])
        ori_w[:, o] *= 1 + alpha * (gain - 1)
    return owner_out
