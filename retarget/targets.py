"""What the robot should do: keypoint, segment and orientation targets from a human motion.

Steps (all positions in the MuJoCo world, placed by :class:`controlmm.frames.HumanToWorld`):

1. **Scale and place** the human: ``transform.to_world(joints)`` (uniform scale).
2. **Per-segment refinement**: walking the human tree from the pelvis, each mapped keypoint
   ``b`` is re-attached to its nearest mapped ancestor ``a`` with the *robot's* rest offset:
   rigid trunk links (pelvis -> hips/spine1, spine3 -> neck/collars/shoulders/head) rotate
   the robot offset with the human pelvis or torso frame; limb bones keep the human bone
   direction with the robot's length. The refined targets have the robot's proportions.
   Then the limb targets (knees, ankles, toes, elbows, wrists) move by
   ``SolverConfig.human_leg_share`` / ``human_arm_share`` toward the scaled human's own joint positions
   (:func:`fit_limbs_to_human`): a robot whose hips are wider than the scaled human's
   brings its knees and feet in under the human's instead of standing on its own hip width,
   its feet kept far enough apart sideways not to overlap (:func:`retarget.foot_targets.space_feet`,
   and whole foot locks moved apart by :func:`retarget.foot_targets.separate_locks`).
3. **Orientations** from bone directions: pelvis frame (hip axis + hips -> pelvis), torso
   frame (collar axis + spine3 -> neck), foot frames (ankle -> toe heading and pitch). The
   trunk's heading counts fully, its tilt at ``TRUNK_TILT``.
4. **Feet**: stance frames (foot low, flat and slow) are detected on the human; in each
   stance the foot is locked flat on the floor at one place and heading (targets ramp in
   over a few frames, and the place is held horizontally a little longer so that feet land
   and lift vertically); in swing the foot targets are lifted so that the human's stance
   height maps to the robot's, and the solver keeps swing feet ``SWING_CLEARANCE`` high
   (contact detection: :mod:`retarget.stance`; the locked and rolling feet:
   :mod:`retarget.foot_targets`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_INDEX
from retarget.foot_targets import STANCE_CLEARANCE, feet_targets, foot_keypoints, separate_locks, space_feet
from retarget.robot_model import RobotModel
from retarget.solver_config import SolverConfig
from retarget.stance import RAMP_SECONDS, detect_contacts, detect_stance, lock_ramp, slowness

FRAME_CHILDREN = {
    "pelvis": ("left_hip", "right_hip", "spine1"),
    "spine3": ("neck", "left_collar", "right_collar", "left_shoulder", "right_shoulder", "head"),
}
"""Keypoints re-attached rigidly to the pelvis / torso frame (the rest are limb bones)."""

SWING_CLEARANCE = 0.015
"""Outside stance the solver keeps the foot at least this high (m): feet are planted or clearly lifted."""
LEG_JOINTS = ("left_knee", "right_knee", "left_ankle", "right_ankle")
ARM_JOINTS = ("left_elbow", "right_elbow", "left_wrist", "right_wrist")
"""Keypoints that :func:`fit_limbs_to_human` moves toward the scaled human's joints."""
TOE_ANKLE = {"left_foot": "left_ankle", "right_foot": "right_ankle"}
"""Toe keypoints move with their ankle (the robot's foot stays rigid)."""
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
        speed_gain: (T, nj) or None: a factor on the velocity term's weight of each joint
            between a frame and the next (the larger of the two frames'), where the output
            turned a joint past its speed limit (:func:`retarget.retarget_motion`).
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
    speed_gain: np.ndarray | None = None


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


def abduct_arms(robot: RobotModel, kp_pos: np.ndarray, torso: np.ndarray, minimum: float) -> None:
    """Keep hanging arms at least ``minimum`` rad away from the body's side (in place).

    A robot whose hips are wider than the scaled human's (G1, H1) cannot let its hands hang
    where the human's do: they would pass through its hip and thigh links. Per frame and
    side, the arm's frontal-plane angle (shoulder -> wrist target in the torso frame,
    lateral against downward) is raised to ``minimum`` by rotating the elbow and wrist
    targets about the torso's forward axis through the shoulder; the correction is weighted
    by how much the arm points down and lies in the frontal plane (none for an arm held
    forward, sideways or up), and is at most ``minimum``, so it is continuous in time. The
    solver's self-clearance term handles the rest (squats, crossing).
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
        length = np.maximum(np.linalg.norm(local, axis=1), 1e-9)
        # Only an arm hanging beside the body passes through the hips: the correction fades
        # with how far the arm points forward or back, and is at most ``minimum`` (an arm
        # reaching across the front is not swung out).
        share = down / length * (1.0 - np.abs(local[:, 0]) / length)
        delta = np.clip(minimum - angle, 0.0, minimum) * share * sign  # rotation about torso x
        if not np.any(delta):
            continue
        c, s_ = np.cos(delta)[:, None], np.sin(delta)[:, None]
        for k in (ke, kw):
            v = kp_pos[:, k] - kp_pos[:, ks]
            along = np.sum(v * x_axis, axis=1, keepdims=True) * x_axis
            perp = v - along
            # Rodrigues about x_axis: perp rotates in the plane normal to x
            kp_pos[:, k] = kp_pos[:, ks] + along + perp * c + np.cross(x_axis, perp) * s_


def fit_limbs_to_human(
    robot: RobotModel, kp_pos: np.ndarray, world: np.ndarray, leg_share: float, arm_share: float
) -> None:
    """Move the limb targets toward the scaled human's joints (in place): the legs' by
    ``leg_share``, the arms' by ``arm_share`` (0: as refined, 1: at the human's joints).

    ``kp_pos`` (T, K, 3): the refined targets (robot proportions); ``world`` (T, 22, 3): the
    scaled human in the world. Knees, ankles, elbows and wrists move toward the human's own
    joint positions, each toe by its ankle's shift (the robot's foot stays rigid); the trunk
    (pelvis, hips, spine, shoulders, head) keeps the robot's proportions. With shares of 1 the
    robot's feet and hands go where the human's are, which is what a position fit to the
    human measures; the solver's self-clearance term keeps the legs and arms apart.
    """
    shift = {}
    for names, share in ((LEG_JOINTS, leg_share), (ARM_JOINTS, arm_share)):
        for name in names:
            if share > 0 and robot.has_keypoint(name):
                k = robot.keypoint_index(name)
                shift[name] = share * (world[:, robot.joints[k]] - kp_pos[:, k])
    for name, delta in shift.items():
        kp_pos[:, robot.keypoint_index(name)] += delta
    for toe, ankle in TOE_ANKLE.items():
        if robot.has_keypoint(toe) and ankle in shift:
            kp_pos[:, robot.keypoint_index(toe)] += shift[ankle]


def build_targets(
    robot: RobotModel,
    joints: np.ndarray,
    fps: float,
    transform: HumanToWorld,
    config: SolverConfig | None = None,
) -> Targets:
    """Targets for ``joints`` (T, 22, 3) human frame (metres, Y up) at ``fps``; ``config``
    (default: the robot's :class:`SolverConfig`) gives ``human_leg_share`` and ``human_arm_share``."""
    config = config if config is not None else SolverConfig(**robot.mapping.solver)
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
    fit_limbs_to_human(robot, kp_pos, world, config.human_leg_share, config.human_arm_share)
    space_feet(robot, kp_pos, world, frames["pelvis"])
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
        else:  # feet: heading and pitch relative to the stance pitch (filled in below), flat foot
            side = kp.joint.split("_")[0]
            on_foot = robot.nodes[k] == robot.feet[side].node
            rot = np.tile(robot.foot_flat_rot[side] if on_foot else node_rest, (t_len, 1, 1))
        ori_kp.append(k)
        ori_axes.append((TRUNK_TILT, TRUNK_TILT, 1.0) if kp.joint in frames else (1.0, 1.0, 1.0))
        ori_rot.append(rot)
        ori_w.append(np.full(t_len, kp.orientation_weight))
    ori_rot_a = np.stack(ori_rot, axis=1) if ori_rot else np.zeros((t_len, 0, 3, 3))
    ori_w_a = np.stack(ori_w, axis=1) if ori_w else np.zeros((t_len, 0))

    stance, lock, clearance, runs, lock_xy = {}, {}, {}, {}, {}
    for side in ("left", "right"):
        flat = detect_stance(joints, fps, side)
        contact, heel, toe = detect_contacts(joints, fps, side, flat)
        # The lock ramps in before and out after contact, but only as far as the human foot
        # has stopped: a fast step lands (and takes off) without skimming the floor.
        alpha = lock_ramp(contact, fps) * np.where(contact, 1.0, slowness(joints, fps, side))
        stance[side], lock[side] = contact, alpha
        # Outside contact the solver keeps the foot SWING_CLEARANCE high; the clearance ramps
        # in with the lock ramping out, so a foot leaving the floor is not yanked up.
        clearance[side] = STANCE_CLEARANCE + SWING_CLEARANCE * (1.0 - alpha)
        # Horizontally the foot holds its contact place a little longer (RAMP_SECONDS more):
        # it lands and takes off vertically instead of sliding in or out.
        alpha_xy = lock_ramp(contact, fps, hold=max(1, int(round(RAMP_SECONDS * fps))))
        lock_xy[side] = alpha_xy
        runs[side] = feet_targets(
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
            config.foot_roll,
            config.roll_lock_gain,
            config.foot_lift,
        )
    separate_locks(robot, kp_pos, world, frames["pelvis"], runs, lock_xy)

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
        speed_gain=None if targets.speed_gain is None else pick(targets.speed_gain),
    )


def stiffer_locks(robot: RobotModel, targets: Targets, factor: float) -> Targets:
    """``targets`` with the stance feet's weights (their keypoints' positions and the ankle's
    orientation) ``factor`` times their own where locked, in proportion to the lock.

    A solve that stiffens another term (the self-clearance's output rungs,
    :mod:`retarget.selfcheck`) stiffens the locks with it: the feet then keep their places and
    the tracked arms and trunk give way (the CMU humanoid sitting down, corpus clip 000012 at
    30 fps: its self-clearance ten times stiffer cleared the arms but slid a planted foot 17 mm
    in a frame; three times stiffer with the locks as stiff cleared them, the feet 0.3 mm)."""
    kp_weight, ori_weight = targets.kp_weight.copy(), targets.ori_weight.copy()
    ori_kp = targets.ori_kp.tolist()
    for side in ("left", "right"):
        gain = 1.0 + targets.lock[side] * (factor - 1.0)  # (T,)
        for k in foot_keypoints(robot, side):
            kp_weight[:, k] *= gain
            if k in ori_kp:
                ori_weight[:, ori_kp.index(k)] *= gain
    return replace(targets, kp_weight=kp_weight, ori_weight=ori_weight)
