"""Assemble a full 22-joint pose sequence from a :class:`BodyPlan`.

Order of construction per frame (all vectorised over frames):
1. pelvis: path + sway towards the planted foot, heading + pelvis twist/pitch/roll; its
   height is the plan's nominal height lowered wherever a planted foot would otherwise be
   out of reach (this produces the walking bob), then smoothed;
2. spine, neck, head by forward kinematics from the pelvis with the bend spread over the
   three spine bones; the head stays level with the heading (gaze stabilisation);
3. collars and shoulders from the chest; arms by two-bone IK towards a wrist target that
   blends a forward-kinematics arm pose (swing, hang) with a gesture target;
4. legs by two-bone IK from the hips to the planned ankles, knees bending towards the
   feet; toes from the foot orientation.
Every joint is parent + unit direction x reference bone length.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from controlmm.corpus.feet import ANKLE_HEIGHT, FootTrack, foot_frame, toe_local
from controlmm.corpus.rig import (
    ANKLE_INDEX,
    COLLAR_INDEX,
    ELBOW_INDEX,
    FOREARM,
    HIP_INDEX,
    KNEE_INDEX,
    REST,
    SHIN,
    SHOULDER_INDEX,
    SIDE_SIGN,
    THIGH,
    TOE_INDEX,
    UPPER_ARM,
    WRIST_INDEX,
    L,
    apply,
    body_rotation,
    heading_vectors,
    hip_offset,
    rot_axis,
    rot_x,
    rot_y,
    rot_z,
    two_bone_ik,
    unit,
)

SIDES = ("left", "right")


def standing_pelvis_height(extension: float = 0.99) -> float:
    """Pelvis height (m) of a person standing on flat feet with legs at ``extension`` of
    their full length (thigh + shin)."""
    return float(ANKLE_HEIGHT - hip_offset("left")[1] + extension * (THIGH["left"] + SHIN["left"]))


@dataclass
class ArmPlan:
    """One arm over T frames.

    Forward-kinematics pose (radians): ``flex`` shoulder flexion (forward +), ``abd``
    abduction (outward +), ``elbow`` flexion (>= 0), ``twist`` humeral inward rotation;
    ``swing`` is the gain (rad per metre of foot separation) of the automatic walking arm
    swing. ``target`` (T, 3) is a wrist target relative to the shoulder in the chest frame
    (x left, y up, z forward), used with weight ``ik`` (T,) in [0, 1]; ``pole`` (T, 3)
    (chest frame) is where the elbow points then. ``elevation`` raises the shoulder girdle.
    """

    flex: np.ndarray
    abd: np.ndarray
    elbow: np.ndarray
    twist: np.ndarray
    swing: np.ndarray
    ik: np.ndarray
    target: np.ndarray
    pole: np.ndarray
    elevation: np.ndarray

    @classmethod
    def hanging(cls, n: int, side: str, rng: np.random.Generator | None = None) -> ArmPlan:
        """Relaxed arm hanging at the side (slightly forward, elbow a little bent)."""
        r = rng if rng is not None else np.random.default_rng(0)
        flex = np.full(n, r.uniform(0.02, 0.15))
        abd = np.full(n, r.uniform(0.08, 0.18))
        elbow = np.full(n, r.uniform(0.15, 0.4))
        twist = np.full(n, r.uniform(0.1, 0.4))
        pole = np.tile(np.array([SIDE_SIGN[side] * 0.5, -0.3, -1.0]), (n, 1))
        return cls(
            flex=flex,
            abd=abd,
            elbow=elbow,
            twist=twist,
            swing=np.zeros(n),
            ik=np.zeros(n),
            target=np.zeros((n, 3)),
            pole=pole,
            elevation=np.zeros(n),
        )


@dataclass
class BodyPlan:
    """Everything that defines a clip, per frame (T frames at ``fps``).

    Angles in radians, lengths in metres, directions in the body frame (x left, y up,
    z forward). ``root_xz``/``yaw``: the path and heading; ``feet``: planned foot tracks;
    ``knee_out``/``knee_up``: how much the knees bend outwards / upwards (sitting on the floor);
    ``pelvis_height``: nominal pelvis height (an upper bound: lowered for leg reach);
    ``pelvis_shift``: (T, 3) pelvis offset in the heading frame; pelvis and spine
    pitch/roll/twist; ``head_pitch``/``head_yaw`` relative to the heading; arms.
    """

    fps: float
    root_xz: np.ndarray
    yaw: np.ndarray
    feet: dict[str, FootTrack]
    pelvis_height: np.ndarray
    arms: dict[str, ArmPlan]
    pelvis_shift: np.ndarray | None = None
    pelvis_pitch: np.ndarray | None = None
    pelvis_roll: np.ndarray | None = None
    pelvis_twist: np.ndarray | None = None
    spine_pitch: np.ndarray | None = None
    spine_roll: np.ndarray | None = None
    spine_twist: np.ndarray | None = None
    head_pitch: np.ndarray | None = None
    head_yaw: np.ndarray | None = None
    sway: float = 0.25
    twist_gain: float = 0.18
    roll_gain: float = 1.2
    knee_out: float = 0.15
    knee_up: float | np.ndarray = 0.0
    reach: float = 0.995
    extras: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(len(self.yaw))

    def get(self, name: str) -> np.ndarray:
        value = getattr(self, name)
        return np.zeros(self.n) if value is None else np.asarray(value, dtype=np.float64)

    def get_shift(self) -> np.ndarray:
        """A copy of ``pelvis_shift`` (T, 3) (zeros when unset), for a family to add to."""
        return (
            np.zeros((self.n, 3))
            if self.pelvis_shift is None
            else np.array(self.pelvis_shift, dtype=np.float64)
        )


@dataclass
class Torso:
    """The trunk of an assembled plan: ``joints`` (T, 22, 3) with the pelvis, spine, neck, head,
    collars and shoulders placed (arms and legs still zero), the pelvis and chest orientations
    (T, 3, 3) and the fore-aft foot separation ``stride`` (T,) that drives the arm swing."""

    joints: np.ndarray
    r_pelvis: np.ndarray
    chest: np.ndarray
    stride: np.ndarray


def torso(plan: BodyPlan) -> Torso:
    """Steps 1-3 of :func:`assemble` without the arms and legs (pelvis, spine, head, shoulders)."""
    n = plan.n
    yaw = plan.get("yaw")
    fwd, left = heading_vectors(yaw)
    joints = np.zeros((n, 22, 3))

    # 1. Pelvis position (xz) and orientation.
    feet = plan.feet
    planted = {s: gaussian_filter1d(feet[s].planted.astype(np.float64), 1.5, mode="nearest") for s in SIDES}
    total = planted["left"] + planted["right"]
    support = planted["left"][:, None] * feet["left"].ankle + planted["right"][:, None] * feet["right"].ankle
    support = support / np.maximum(total, 1e-6)[:, None]
    root = np.stack([plan.root_xz[:, 0], np.zeros(n), plan.root_xz[:, 1]], -1)
    lateral = ((support - root) * left).sum(-1) * np.clip(total, 0.0, 1.0)
    sway = gaussian_filter1d(plan.sway * lateral, 1.0, mode="nearest")
    shift = plan.pelvis_shift if plan.pelvis_shift is not None else np.zeros((n, 3))
    pelvis = root + left * (sway + shift[:, 0])[:, None] + fwd * shift[:, 2][:, None]
    stride = ((feet["left"].ankle - feet["right"].ankle) * fwd).sum(-1)
    twist = plan.get("pelvis_twist") - np.clip(plan.twist_gain * stride, -0.25, 0.25)
    roll = plan.get("pelvis_roll") - plan.roll_gain * sway
    pitch = plan.get("pelvis_pitch")
    r_pelvis = body_rotation(yaw + twist, pitch, roll)
    pelvis[:, 1] = _pelvis_height(plan, pelvis, r_pelvis) + shift[:, 1]
    joints[:, 0] = pelvis

    # 2. Spine, neck, head.
    sp, sr, st = plan.get("spine_pitch"), plan.get("spine_roll"), plan.get("spine_twist") - 1.6 * twist
    rel = [rot_y(k * st) @ rot_x(k * sp) @ rot_z(-k * sr) for k in (1 / 3, 2 / 3, 1.0)]
    parent = pelvis
    for j, r in zip((3, 6, 9), rel, strict=True):
        parent = parent + apply(r_pelvis @ r, REST[j]) * L[j]
        joints[:, j] = parent
    chest = r_pelvis @ rel[2]
    joints[:, 12] = joints[:, 9] + apply(chest, REST[12]) * L[12]
    lean = pitch + sp
    head_rot = body_rotation(
        yaw + plan.get("head_yaw") + 0.3 * (twist + st),
        plan.get("head_pitch") + 0.45 * lean,
        0.4 * (roll + sr),
    )
    joints[:, 15] = joints[:, 12] + apply(head_rot, REST[15]) * L[15]

    # 3. Shoulder girdle.
    for side in SIDES:
        sign = SIDE_SIGN[side]
        elev = rot_z(sign * plan.arms[side].elevation)
        c, s = COLLAR_INDEX[side], SHOULDER_INDEX[side]
        joints[:, c] = joints[:, 9] + apply(chest @ elev, REST[c]) * L[c]
        joints[:, s] = joints[:, c] + apply(chest @ elev, REST[s]) * L[s]
    return Torso(joints=joints, r_pelvis=r_pelvis, chest=chest, stride=stride)


def chest_target(plan: BodyPlan, side: str, world: np.ndarray) -> np.ndarray:
    """A world-space wrist target (T, 3) or (3,) as the chest-frame offset from the ``side``
    shoulder (what :class:`ArmPlan` ``target`` holds), for the plan as it stands."""
    tr = torso(plan)
    rel = (
        np.broadcast_to(np.asarray(world, dtype=np.float64), (plan.n, 3)) - tr.joints[:, SHOULDER_INDEX[side]]
    )
    return np.einsum("tji,tj->ti", tr.chest, rel)


def assemble(plan: BodyPlan) -> np.ndarray:
    """Build joint positions (T, 22, 3), metres, Y up, from a plan."""
    tr = torso(plan)
    joints, r_pelvis, chest = tr.joints, tr.r_pelvis, tr.chest
    feet = plan.feet
    pelvis = joints[:, 0]
    for side in SIDES:
        joints[:, ELBOW_INDEX[side]], joints[:, WRIST_INDEX[side]] = _arm(
            plan, side, chest, joints[:, SHOULDER_INDEX[side]], tr.stride
        )

    # 4. Legs.
    for side in SIDES:
        track = feet[side]
        hip = pelvis + apply(r_pelvis, hip_offset(side))
        joints[:, HIP_INDEX[side]] = hip
        pole = knee_pole(track.yaw, r_pelvis, side, plan.knee_out)
        pole = unit(
            pole + np.asarray(plan.knee_up, dtype=np.float64).reshape(-1, 1) * np.array([0.0, 1.0, 0.0])
        )
        knee, ankle = two_bone_ik(hip, track.ankle, pole, THIGH[side], SHIN[side], max_reach=0.9995)
        joints[:, KNEE_INDEX[side]] = knee
        joints[:, ANKLE_INDEX[side]] = ankle
        joints[:, TOE_INDEX[side]] = ankle + apply(foot_frame(track.yaw, track.pitch), toe_local(side))
    return joints


def knee_pole(foot_yaw: np.ndarray, r_pelvis: np.ndarray, side: str, knee_out: float) -> np.ndarray:
    """Direction (T, 3) the knee bends towards: the foot's and the pelvis' forward, a little out."""
    foot_fwd, _ = heading_vectors(foot_yaw)
    pelvis_fwd = apply(r_pelvis, np.array([0.0, 0.0, 1.0]))
    pelvis_left = apply(r_pelvis, np.array([1.0, 0.0, 0.0]))
    return unit(foot_fwd + 0.6 * pelvis_fwd + knee_out * SIDE_SIGN[side] * pelvis_left)


def _pelvis_height(plan: BodyPlan, pelvis: np.ndarray, r_pelvis: np.ndarray) -> np.ndarray:
    """Nominal height lowered so that every planted foot stays within reach (hard limit) and
    a swinging foot can reach its path (soft: at most 8 cm lower), then smoothed."""
    height = plan.get("pelvis_height")
    limit = np.full(plan.n, np.inf)
    for side in SIDES:
        track = plan.feet[side]
        hip_rel = apply(r_pelvis, hip_offset(side))
        reach = plan.reach * (THIGH[side] + SHIN[side])
        horiz = np.linalg.norm((pelvis + hip_rel - track.ankle)[:, [0, 2]], axis=-1)
        vert = np.sqrt(np.maximum(reach**2 - horiz**2, 1e-4))
        lim = track.ankle[:, 1] + vert - hip_rel[:, 1]
        # Planted frames and one frame around them are hard limits.
        hard = track.planted | np.roll(track.planted, 1) | np.roll(track.planted, -1)
        swing_ok = ~hard & (horiz < 0.9 * reach)
        soft = np.maximum(lim, height - 0.08)
        limit = np.where(hard, np.minimum(limit, lim), np.where(swing_ok, np.minimum(limit, soft), limit))
    # Lower the nominal curve by a widened, blurred copy of its excess over the limits: the
    # pelvis dips smoothly where the legs are spread instead of following the limits' cusps.
    excess = np.maximum(height - limit, 0.0)
    excess = gaussian_filter1d(maximum_filter1d(excess, 7, mode="nearest"), 2.0, mode="nearest")
    y = height - excess
    for _ in range(3):
        y = np.minimum(gaussian_filter1d(np.minimum(y, limit), 1.0, mode="nearest"), limit)
    return y


def _arm(
    plan: BodyPlan, side: str, chest: np.ndarray, shoulder: np.ndarray, stride: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    arm = plan.arms[side]
    sign = SIDE_SIGN[side]
    flex = arm.flex - sign * arm.swing * stride  # arm swings opposite to the same-side leg
    seg = rot_x(-flex) @ rot_z(sign * arm.abd)
    upper = apply(chest @ seg, np.array([0.0, -1.0, 0.0]))
    hinge = apply(chest @ seg, np.array([1.0, 0.0, 0.0]))
    fore = apply(rot_axis(upper, sign * arm.twist) @ rot_axis(hinge, -arm.elbow), upper)
    la, lf = UPPER_ARM[side], FOREARM[side]
    elbow_fk = shoulder + upper * la
    wrist_fk = elbow_fk + fore * lf
    w = np.clip(arm.ik, 0.0, 1.0)[:, None]
    target = (1.0 - w) * wrist_fk + w * (shoulder + apply(chest, arm.target))
    default_pole = apply(chest, np.array([sign * 0.4, -0.4, -1.0]))
    pole = (
        (1.0 - w) * (elbow_fk - 0.5 * (shoulder + wrist_fk))
        + w * apply(chest, arm.pole)
        + 0.02 * default_pole
    )
    return two_bone_ik(shoulder, target, pole, la, lf, max_reach=0.995)
