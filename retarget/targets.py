"""What the robot should do: keypoint, segment and orientation targets from a human motion.

Steps (all positions in the MuJoCo world, placed by :class:`controlmm.frames.HumanToWorld`):

1. **Scale and place** the human: ``transform.to_world(joints)`` (uniform scale).
2. **Per-segment refinement**: walking the human tree from the pelvis, each mapped keypoint
   ``b`` is re-attached to its nearest mapped ancestor ``a`` with the *robot's* rest offset:
   rigid trunk links (pelvis -> hips/spine1, spine3 -> neck/collars/shoulders/head) rotate
   the robot offset with the human pelvis or torso frame; limb bones keep the human bone
   direction with the robot's length. The refined targets have the robot's proportions.
3. **Orientations** from bone directions: pelvis frame (hip axis + hips -> pelvis), torso
   frame (collar axis + spine3 -> neck), foot frames (ankle -> toe heading and pitch). The
   trunk's heading counts fully, its tilt at ``TRUNK_TILT``.
4. **Feet**: stance frames (foot low, flat and slow) are detected on the human; in each
   stance the foot is locked flat on the floor at one place and heading (targets ramp in
   over a few frames, and the place is held horizontally a little longer so that feet land
   and lift vertically); in swing the foot targets are lifted so that the human's stance
   height maps to the robot's, and the solver keeps swing feet ``SWING_CLEARANCE`` high.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_INDEX
from retarget.kinematics import so3_exp, so3_log
from retarget.robot_model import RobotModel

FRAME_CHILDREN = {
    "pelvis": ("left_hip", "right_hip", "spine1"),
    "spine3": ("neck", "left_collar", "right_collar", "left_shoulder", "right_shoulder", "head"),
}
"""Keypoints re-attached rigidly to the pelvis / torso frame (the rest are limb bones)."""

STANCE_ANKLE_HEIGHT = 0.085
STANCE_TOE_HEIGHT = 0.05
STANCE_SPEED = 0.35
"""Human stance test (HumanML3D metres, m/s): ankle and toe low and both slower than this."""

CONTACT_RISE = 0.02
"""A heel (ankle) or toe joint within this of its flat-stance height (HumanML3D metres) may be on the floor."""
CONTACT_SPEED = 0.5
"""...and is on it when slower than this (m/s; the ankle circles the heel during a heel strike)."""

STANCE_MIN_SECONDS = 0.15
STANCE_SMOOTH_SECONDS = 0.075
MERGE_GAP_SECONDS = 0.4
MERGE_DISTANCE = 0.05
"""Two stances of a foot closer than this in time (s) and place (m), with the foot kept low, are one."""
SWING_CLEARANCE = 0.015
"""Outside stance the solver keeps the foot at least this high (m): feet are planted or clearly lifted."""
RAMP_SECONDS = 0.1
"""Foot locks ramp in and out over this time (s); horizontally they hold this much longer."""
RAMP_SPEED = 1.0
"""The ramp of a lock fades with the human foot's horizontal speed, to nothing at this (m/s)."""
STANCE_CLEARANCE = 0.001
"""Locked feet stand this high (m) above the floor (the solver's floor margin)."""
PITCH_SMOOTH_SECONDS = 0.05
"""Gaussian sigma (s) of a contact foot's pitch (flat, heel strike, toe-off) over time."""
LOCK_GAIN = 30.0
"""Weight multiplier of the foot targets during stance (locked feet)."""
TRUNK_TILT = 0.3
"""Weight factor of the pelvis/torso tilt (roll, pitch) against their heading: the human's
neutral trunk tilt is not well defined from joints, the heading is."""


@dataclass
class Targets:
    """Solver targets for T frames (world frame, metres).

    Attributes:
        fps: frame rate of the targets (the motion's).
        transform: the human -> world transform used.
        human_world: (T, 22, 3) the scaled human in the world (before refinement).
        kp_pos: (T, K, 3) refined keypoint targets; kp_weight: (T, K).
        seg_parent, seg_child: (S,) keypoint indices; seg_vec: (T, S, 3); seg_weight: (S,).
        ori_kp: (O,) keypoint indices; ori_rot: (T, O, 3, 3) target world rotation of the
            keypoint's node; ori_weight: (T, O).
        stance: {"left"|"right": (T,) bool} human stance frames.
        lock: {"left"|"right": (T,) float in [0, 1]} how locked each foot is.
        clearance: {"left"|"right": (T,)} minimum height (m) of the foot's collision points.
    """

    fps: float
    transform: HumanToWorld
    human_world: np.ndarray
    kp_pos: np.ndarray
    kp_weight: np.ndarray
    seg_parent: np.ndarray
    seg_child: np.ndarray
    seg_vec: np.ndarray
    seg_weight: np.ndarray
    ori_kp: np.ndarray
    ori_rot: np.ndarray
    ori_weight: np.ndarray
    ori_axis_weight: np.ndarray
    stance: dict[str, np.ndarray]
    lock: dict[str, np.ndarray]
    clearance: dict[str, np.ndarray]


def _unit(v: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = v / np.maximum(n, 1e-9)
    if fallback is not None:
        out = np.where(n > 1e-9, out, fallback)
    return out


def frame_from_axes(left: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) with y along ``left`` and z as close to ``up`` as possible (x = y x up)."""
    y = _unit(left)
    x = _unit(np.cross(y, up), np.array([1.0, 0.0, 0.0]))
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1)


def human_frames(world: np.ndarray) -> dict[str, np.ndarray]:
    """Pelvis and torso frames (T, 3, 3) of a scaled human in world axes (T, 22, 3).

    Pelvis: y along the hip axis, z toward the pelvis joint from the hips' midpoint (on the
    HumanML3D skeleton spine1 leans ~17 deg back of that line when standing). Torso: y along
    the collar axis, z from spine3 toward the neck. Both are about the identity for an
    upright human facing world +X.
    """
    j = JOINT_INDEX
    hips = (world[:, j["left_hip"]] + world[:, j["right_hip"]]) / 2
    pelvis = frame_from_axes(world[:, j["left_hip"]] - world[:, j["right_hip"]], world[:, j["pelvis"]] - hips)
    torso = frame_from_axes(
        world[:, j["left_collar"]] - world[:, j["right_collar"]], world[:, j["neck"]] - world[:, j["spine3"]]
    )
    return {"pelvis": pelvis, "spine3": torso}


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


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) runs of True."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return list(zip(edges[::2], edges[1::2]))


def detect_stance(joints: np.ndarray, fps: float, side: str) -> np.ndarray:
    """Human stance frames (T,) bool of one foot from HumanML3D joints (metres, Y up).

    A stance frame has the ankle below 8.5 cm, the toe below 5 cm and both moving slower than
    0.35 m/s horizontally (positions smoothed over ~0.075 s first, so that jittery input
    still plants its feet); gaps of one frame are filled and runs shorter than 0.15 s dropped.
    """
    a, t = joints[:, JOINT_INDEX[f"{side}_ankle"]], joints[:, JOINT_INDEX[f"{side}_foot"]]
    n = len(joints)
    if n >= 4:
        sigma = STANCE_SMOOTH_SECONDS * fps
        a = gaussian_filter1d(a.astype(np.float64), sigma, axis=0, mode="nearest")
        t = gaussian_filter1d(t.astype(np.float64), sigma, axis=0, mode="nearest")
    if n < 2:
        return np.array([a[0, 1] < STANCE_ANKLE_HEIGHT and t[0, 1] < STANCE_TOE_HEIGHT])

    def speed(p: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1) * fps
        return np.maximum(np.concatenate([d[:1], d]), np.concatenate([d, d[-1:]]))

    ok = (
        (a[:, 1] < STANCE_ANKLE_HEIGHT)
        & (t[:, 1] < STANCE_TOE_HEIGHT)
        & (speed(a) < STANCE_SPEED)
        & (speed(t) < STANCE_SPEED)
    )
    for s, e in _segments(~ok):  # fill one-frame gaps inside stance
        if 0 < s and e < n and e - s <= 1:
            ok[s:e] = True
    min_len = max(2, int(round(STANCE_MIN_SECONDS * fps)))
    for s, e in _segments(ok):
        if e - s < min_len:
            ok[s:e] = False
    # One stance when the foot comes back to (almost) the same place soon after leaving it.
    runs = _segments(ok)
    foot = (a + t)[:, [0, 2]] / 2
    for (s0, e0), (s1, e1) in zip(runs[:-1], runs[1:]):
        if (s1 - e0) <= MERGE_GAP_SECONDS * fps:
            moved = np.linalg.norm(foot[s0:e0].mean(axis=0) - foot[s1:e1].mean(axis=0))
            low = np.all(a[e0:s1, 1] < STANCE_ANKLE_HEIGHT + 0.03) and np.all(
                t[e0:s1, 1] < STANCE_TOE_HEIGHT + 0.03
            )
            if moved < MERGE_DISTANCE and low:
                ok[e0:s1] = True
    return ok


def abduct_arms(robot: RobotModel, kp_pos: np.ndarray, torso: np.ndarray, minimum: float) -> None:
    """Keep hanging arms at least ``minimum`` rad away from the body's side (in place).

    A robot whose hips are wider than the scaled human's (G1, H1) cannot let its hands hang
    where the human's do: they would pass through its hip and thigh links. Per frame and
    side, the arm's frontal-plane angle (shoulder -> wrist target in the torso frame,
    lateral against downward) is raised to ``minimum`` by rotating the elbow and wrist
    targets about the torso's forward axis through the shoulder; the correction is weighted
    by how much the arm points down (none for an arm held forward, sideways or up), so it is
    continuous in time. The solver's self-clearance term handles the rest (squats, crossing).
    """
    x_axis = torso[..., :, 0]  # (T, 3) torso forward
    for sign, side in ((1.0, "left"), (-1.0, "right")):
        names = [f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist"]
        if not all(robot.has_keypoint(n) for n in names):
            continue
        ks, ke, kw = (robot.keypoint_index(n) for n in names)
        arm = kp_pos[:, kw] - kp_pos[:, ks]
        local = np.einsum("tji,tj->ti", torso, arm)  # torso frame: x forward, y left, z up
        down = np.maximum(-local[:, 2], 0.0)
        lateral = sign * local[:, 1]
        angle = np.arctan2(lateral, np.maximum(down, 1e-9))
        share = down / np.maximum(np.linalg.norm(local, axis=1), 1e-9)
        delta = np.maximum(minimum - angle, 0.0) * share * sign  # rotation about torso x
        if not np.any(delta):
            continue
        c, s_ = np.cos(delta)[:, None], np.sin(delta)[:, None]
        for k in (ke, kw):
            v = kp_pos[:, k] - kp_pos[:, ks]
            along = np.sum(v * x_axis, axis=1, keepdims=True) * x_axis
            perp = v - along
            # Rodrigues about x_axis: perp rotates in the plane normal to x
            kp_pos[:, k] = kp_pos[:, ks] + along + perp * c + np.cross(x_axis, perp) * s_


def _ramp(stance: np.ndarray, fps: float, hold: int = 0) -> np.ndarray:
    """1 in stance (and ``hold`` frames around it), then falling linearly to 0 over RAMP_SECONDS."""
    r = max(1, int(round(RAMP_SECONDS * fps)))
    dist = np.full(len(stance), np.inf)
    idx = np.flatnonzero(stance)
    if len(idx):
        frames = np.arange(len(stance))
        dist = np.abs(frames[:, None] - idx[None, :]).min(axis=1)
    return np.clip(1.0 - np.maximum(dist - hold, 0) / (r + 1), 0.0, 1.0)


def detect_contacts(
    joints: np.ndarray, fps: float, side: str, stance: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Human foot contact per frame: (contact, heel_down, toe_down), each (T,) bool.

    ``heel_down``: the ankle within ``CONTACT_RISE`` of its flat-stance height and slower than
    ``CONTACT_SPEED`` (heel strike, flat foot); ``toe_down``: the toe joint within
    ``CONTACT_RISE`` of its flat-stance height and slower than ``STANCE_SPEED`` (the pivot of
    a toe-off, tiptoes). ``contact`` = flat stance (:func:`detect_stance`) or either, with
    one-frame gaps filled and one-frame runs dropped. Heights are relative to the clip's own
    flat-stance heights of that foot (HumanML3D puts the floor at the lowest joint).
    """
    st = detect_stance(joints, fps, side) if stance is None else stance
    a, t = joints[:, JOINT_INDEX[f"{side}_ankle"]], joints[:, JOINT_INDEX[f"{side}_foot"]]
    n = len(joints)
    if n >= 4:
        sigma = STANCE_SMOOTH_SECONDS * fps
        a = gaussian_filter1d(a.astype(np.float64), sigma, axis=0, mode="nearest")
        t = gaussian_filter1d(t.astype(np.float64), sigma, axis=0, mode="nearest")
    if n < 2:
        return st.copy(), st.copy(), st.copy()

    def speed(p: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1) * fps
        return np.minimum(np.concatenate([d[:1], d]), np.concatenate([d, d[-1:]]))

    low = max(1, n // 20)
    a_ref = float(np.median(a[st, 1])) if st.any() else float(np.sort(a[:, 1])[:low].mean())
    t_ref = float(np.median(t[st, 1])) if st.any() else float(np.sort(t[:, 1])[:low].mean())
    heel = (a[:, 1] < a_ref + CONTACT_RISE) & (speed(a) < CONTACT_SPEED)
    toe = (t[:, 1] < t_ref + CONTACT_RISE) & (speed(t) < STANCE_SPEED)
    contact = st | heel | toe
    for s, e in _segments(~contact):  # fill one-frame gaps
        if 0 < s and e < n and e - s <= 1:
            contact[s:e] = True
    for s, e in _segments(contact):
        if e - s < 2:
            contact[s:e] = False
    return contact, heel & contact, toe & contact


def _slowness(joints: np.ndarray, fps: float, side: str) -> np.ndarray:
    """(T,) 1 for a human foot at rest horizontally, falling to 0 at ``RAMP_SPEED``."""
    feet = joints[:, [JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]]][..., [0, 2]]
    if len(feet) < 2:
        return np.ones(len(feet))
    step = np.linalg.norm(np.diff(feet, axis=0), axis=2).max(axis=1) * fps  # (T-1,)
    speed = np.minimum(np.r_[step[:1], step], np.r_[step, step[-1:]])  # arriving at / leaving rest counts
    return np.clip(1.0 - speed / RAMP_SPEED, 0.0, 1.0)


def foot_pivots(robot: RobotModel, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Heel and toe pivots (3,) of a foot in its node frame: the centres of its rearmost and
    foremost sole points (the collision points within 3 mm of the sole, rest pose, world +X
    forward). A foot rolling about a pivot keeps that point's height and place."""
    f = robot.feet[side]
    rot = robot.rest.rot[0, f.node]
    world = f.points @ rot.T
    low = world[:, 2] - f.radius
    sole = low <= low.min() + 0.003
    x = world[:, 0]
    front = sole & (x >= x[sole].max() - 0.01)
    back = sole & (x <= x[sole].min() + 0.01)
    return f.points[back].mean(axis=0), f.points[front].mean(axis=0)


def build_targets(robot: RobotModel, joints: np.ndarray, fps: float, transform: HumanToWorld) -> Targets:
    """Targets for ``joints`` (T, 22, 3) human frame (metres, Y up) at ``fps``."""
    joints = np.asarray(joints, dtype=np.float64)
    world = np.asarray(transform.to_world(joints), dtype=np.float64)
    t_len, k_len = len(world), len(robot.joints)
    frames = human_frames(world)
    rest = robot.rest_keypoints
    mapping = robot.mapping
    kp_pos = np.zeros((t_len, k_len, 3))
    seg_parent, seg_child, seg_weight = [], [], []
    hips = [robot.keypoint_index(j) for j in ("left_hip", "right_hip") if robot.has_keypoint(j)]
    for k in range(k_len):
        name = robot.keypoint_names[k]
        h_k = world[:, robot.joints[k]]
        a = robot.human_parent_keypoint(k)
        if a is None:
            if name == "pelvis" and len(hips) == 2:
                # The scale matches hip heights: hang the pelvis above the scaled hip centre.
                centre = world[:, [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]].mean(axis=1)
                kp_pos[:, k] = centre + frames["pelvis"] @ (rest[k] - rest[hips].mean(axis=0))
            else:
                kp_pos[:, k] = h_k
            continue
        parent = robot.keypoint_names[a]
        if parent in FRAME_CHILDREN and name in FRAME_CHILDREN[parent]:
            kp_pos[:, k] = kp_pos[:, a] + frames[parent] @ (rest[k] - rest[a])
        else:
            length = np.linalg.norm(rest[k] - rest[a])
            kp_pos[:, k] = kp_pos[:, a] + length * _unit(h_k - world[:, robot.joints[a]])
        if mapping.keypoints[k].segment_weight > 0:
            seg_parent.append(a)
            seg_child.append(k)
            seg_weight.append(mapping.keypoints[k].segment_weight)
    if mapping.arm_abduction > 0:
        abduct_arms(robot, kp_pos, frames["spine3"], mapping.arm_abduction)
    kp_weight = np.tile([kp.position_weight for kp in mapping.keypoints], (t_len, 1)).astype(float)
    seg_vec = kp_pos[:, seg_child] - kp_pos[:, seg_parent] if seg_child else np.zeros((t_len, 0, 3))

    # Orientation targets: R_target = R_human_frame @ R_rest(node).
    ori_kp, ori_rot, ori_w, ori_axes = [], [], [], []
    for k, kp in enumerate(mapping.keypoints):
        if kp.orientation_weight <= 0:
            continue
        node_rest = robot.rest.rot[0, robot.nodes[k]]
        if kp.joint in frames:
            rot = frames[kp.joint] @ node_rest
        else:  # feet: heading and pitch relative to the stance pitch (filled in below)
            rot = np.tile(node_rest, (t_len, 1, 1))
        ori_kp.append(k)
        ori_axes.append((TRUNK_TILT, TRUNK_TILT, 1.0) if kp.joint in frames else (1.0, 1.0, 1.0))
        ori_rot.append(rot)
        ori_w.append(np.full(t_len, kp.orientation_weight))
    ori_rot_a = np.stack(ori_rot, axis=1) if ori_rot else np.zeros((t_len, 0, 3, 3))
    ori_w_a = np.stack(ori_w, axis=1) if ori_w else np.zeros((t_len, 0))

    stance, lock, clearance = {}, {}, {}
    for side in ("left", "right"):
        flat = detect_stance(joints, fps, side)
        contact, heel, toe = detect_contacts(joints, fps, side, flat)
        # The lock ramps in before and out after contact, but only as far as the human foot
        # has stopped: a fast step lands (and takes off) without skimming the floor.
        alpha = _ramp(contact, fps) * np.where(contact, 1.0, _slowness(joints, fps, side))
        stance[side], lock[side] = contact, alpha
        # Outside contact the solver keeps the foot SWING_CLEARANCE high; the clearance ramps
        # in with the lock ramping out, so a foot leaving the floor is not yanked up.
        clearance[side] = STANCE_CLEARANCE + SWING_CLEARANCE * (1.0 - alpha)
        # Horizontally the foot holds its contact place a little longer (RAMP_SECONDS more):
        # it lands and takes off vertically instead of sliding in or out.
        alpha_xy = _ramp(contact, fps, hold=max(1, int(round(RAMP_SECONDS * fps))))
        _feet_targets(
            robot,
            side,
            world,
            fps,
            flat,
            contact,
            heel,
            toe,
            alpha,
            alpha_xy,
            kp_pos,
            kp_weight,
            ori_kp,
            ori_rot_a,
            ori_w_a,
        )

    return Targets(
        fps=float(fps),
        transform=transform,
        human_world=world,
        kp_pos=kp_pos,
        kp_weight=kp_weight,
        seg_parent=np.array(seg_parent, dtype=int),
        seg_child=np.array(seg_child, dtype=int),
        seg_vec=seg_vec,
        seg_weight=np.array(seg_weight, dtype=float),
        ori_kp=np.array(ori_kp, dtype=int),
        ori_rot=ori_rot_a,
        ori_weight=ori_w_a,
        ori_axis_weight=np.array(ori_axes, dtype=float).reshape(-1, 3),
        stance=stance,
        lock=lock,
        clearance=clearance,
    )


def _feet_targets(
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
    rest_rot = robot.rest.rot[0, foot_node]
    rest_pos = robot.rest.pos[0, foot_node]
    heading, elevation = foot_heading_pitch(world, side)
    ref = flat_stance if flat_stance.any() else contact
    flat = np.median(elevation[ref]) if ref.any() else np.median(elevation)
    # Swing: shift the foot keypoints vertically so the human stance height is the robot's.
    ankle_rest_h = robot.rest_keypoints[ka, 2] - robot.floor_z
    ref_h = kp_pos[ref, ka, 2] if ref.any() else np.sort(kp_pos[:, ka, 2])[: max(1, len(kp_pos) // 20)]
    lift = ankle_rest_h - float(np.median(ref_h))
    for k in same_node:
        kp_pos[:, k, 2] += lift
    pitch = -(elevation - flat)  # > 0: toe down (heel up)
    swing_rot = rot_z(heading) @ rot_y(pitch) @ rest_rot
    lock_rot = swing_rot.copy()
    lock_node = kp_pos[:, ka] - np.einsum("tij,j->ti", swing_rot, robot.offsets[ka])
    runs = _segments(contact)
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
        height = rest_pos[2] - robot.floor_z + STANCE_CLEARANCE
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


def take_frames(targets: Targets, idx: np.ndarray, fps: float) -> Targets:
    """The targets of frames ``idx`` (F,), labelled with frame rate ``fps``."""
    pick = lambda a: a[idx]  # noqa: E731
    return Targets(
        fps=fps,
        transform=targets.transform,
        human_world=pick(targets.human_world),
        kp_pos=pick(targets.kp_pos),
        kp_weight=pick(targets.kp_weight),
        seg_parent=targets.seg_parent,
        seg_child=targets.seg_child,
        seg_vec=pick(targets.seg_vec),
        seg_weight=targets.seg_weight,
        ori_kp=targets.ori_kp,
        ori_rot=pick(targets.ori_rot),
        ori_weight=pick(targets.ori_weight),
        ori_axis_weight=targets.ori_axis_weight,
        stance={k: pick(v) for k, v in targets.stance.items()},
        lock={k: pick(v) for k, v in targets.lock.items()},
        clearance={k: pick(v) for k, v in targets.clearance.items()},
    )
