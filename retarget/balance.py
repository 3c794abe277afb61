"""Balance: keep the zero-moment point where the stance ankles' motors can hold it.

A human's centre of pressure runs from heel to toe while it stands on one foot, 15-25 cm
ahead of the ankle at push-off. A robot whose ankle motors are weak for its mass (H1: 40 N m
for 51 kg, T1: 20 N m for 32 kg) can hold it only ``limit / (m g)`` from the ankle (8 and
6.5 cm): with the human's centre-of-mass path it needs more ankle torque than its motors
have, and ``controlmm validate`` fails it (``torque_limit``).

The cart-table model (Kajita et al., 2003) gives the zero-moment point of a body whose centre
of mass ``c`` moves at a height ``z``: ``p = c_xy - (z / g) c''_xy``. Moving the centre of mass
horizontally by ``d`` (T, 2) moves it by ``A d = d - (z / g) d''``: a shift that swings with
the steps moves it more than its own size (at a step a second, 1 + (2 pi)^2 z / g: about 4 for
T1's 0.59 m). Per output frame:

1. The centre of mass (every body's, through the replayed frames), its second differences and
   ``p``; the feet on the floor (their geoms within ``SUPPORT_HEIGHT``).
2. The weight put at ``p`` loads each ankle hinge of a single support foot (its hinge joints
   whose anchors lie within ``ANKLE_SPAN`` of the foot's lowest one) with
   ``m g ((p - anchor) x z) . axis``; in double support the two feet's hinges of the same rank
   share it, except about an axis along which the feet stand apart (the support spans that);
   frames with another body on the floor (a knee, a hand) are left alone.
   The load counts ``p`` only as far as the soles of the feet on the floor reach along the
   lever (the rest is a residual wrench, not torque: G1's 50 N m ankles hold its 33 kg on the
   toe); ``p``'s distance past ``MARGIN`` of the motors, along the lever, is how far it must
   move.
3. :func:`balance_shift` solves ``d`` for the whole clip by least squares,
   ``sum_supported |A d - e|^2 + RIDGE |d|^2``, once the load (as ``controlmm validate`` weighs
   it: the torque ratio averaged over ``WINDOW_S``) is over ``TRIGGER`` somewhere, and then
   again from each new solve while it is over ``GOAL``.

``retarget_motion`` then moves the human's joints, all but the feet (the knees by half), by the
accumulated shift and solves again (``SolverConfig.balance_iterations`` times at most), and
keeps the solve with the lowest load. The estimate is a model: it leaves out the limbs'
angular momentum and the check's own support contacts (which may put the weight elsewhere).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import scipy.sparse as sp
from scipy.ndimage import uniform_filter1d
from scipy.sparse.linalg import spsolve

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_INDEX
from retarget.actuators import joint_torque_limits
from retarget.metrics import Replay, foot_steps, geom_lowest_z
from retarget.robot_model import RobotModel

G = 9.81
SUPPORT_HEIGHT = 0.02
"""Metres above the floor within which a geom's lowest point carries weight (as in
``controlmm validate``, ``CheckConfig.support_height_m``)."""
ANKLE_SPAN = 0.05
"""Metres (times the robot's scale) within which a hinge's anchor is the ankle's: G1's and
T1's pitch and roll anchors coincide, their knees are 30 cm up."""
MARGIN = 0.7
"""Share of an ankle motor the shift aims to leave the zero-moment point's load at."""
TRIGGER = 0.9
"""The estimated torque ratio, averaged over ``WINDOW_S``, above which a clip is balanced
(the model leaves out the limbs' momentum: H1's corpus clip 000018 fails the check at 1.02
where it estimates 0.97)."""
GOAL = 0.75
"""...and the ratio its later solves aim at: the model's estimate runs 10-15 % under the
check's sustained torque at its end (T1's corpus clips 000002, 000004 and 000011: 0.82-0.97
estimated, 1.02 in the check)."""
WINDOW_S = 0.5
"""Seconds of ``controlmm validate``'s sustained torque window."""
RIDGE = 0.01
"""Weight of the shift's own size against the excess (both in metres)."""
MAX_SHIFT = 0.1
"""Largest shift (metres, times the robot's scale) per solve."""
FIT_GIVE = 0.01
"""Metres (mean over keypoints and frames) a balanced solve may move further from the
unmoved targets than the first solve."""
STANCE_HEIGHT = 0.01
"""Metres above the floor within which a foot stands (``CheckConfig.stance_height_m``)."""
SLIDE_SPEED = 0.2
"""m/s a foot on the floor may slide (``controlmm validate``'s ``max_foot_slide_speed``): a
balanced solve may not slide one faster, unless the first solve did."""
HELD_BY_MODEL = 1.0
"""A balanced solve whose load stays above this is dropped: it gives up fit and still asks
more of the motors than they have."""
APART = 0.7
"""In double support, an axis whose lever runs within acos(APART) of the line between the
ankles is held by the support itself."""


@dataclass(frozen=True)
class Ankles:
    """The ankle hinges of each foot, in the same order (a leg may have one: H1's pitch).

    Attributes:
        joints: side -> MuJoCo joint ids, from the foot up.
        limits: side -> (J,) motor torque limits (N m; NaN: none).
    """

    joints: dict[str, np.ndarray]
    limits: dict[str, np.ndarray]


def ankle_hinges(robot: RobotModel) -> Ankles:
    """The hinge joints at each ankle: from the foot's body up, those whose anchors (at the
    model's reference pose) lie within ``ANKLE_SPAN * scale`` of the first."""
    model = robot.model
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    joints, limits = {}, {}
    for side in ("left", "right"):
        body = int(robot.tree.node_body[robot.feet[side].node])
        chain: list[int] = []
        while body > 0:
            chain += [
                j
                for j in range(model.njnt)
                if model.jnt_bodyid[j] == body and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
            ]
            body = int(model.body_parentid[body])
        if chain:
            first = data.xanchor[chain[0]]
            span = ANKLE_SPAN * robot.scale
            chain = [j for j in chain if np.linalg.norm(data.xanchor[j] - first) < span]
        joints[side] = np.array(chain, dtype=int)
        limits[side] = joint_torque_limits(model, chain) if chain else np.zeros(0)
    return Ankles(joints, limits)


def centre_of_mass(robot: RobotModel, rep: Replay) -> tuple[np.ndarray, float]:
    """(T, 3) the robot's centre of mass in the replayed frames and its mass (kg)."""
    model = robot.model
    root = int(model.body_rootid[robot.tree.node_body[0]])
    bodies = np.flatnonzero(model.body_rootid == root)
    mass = model.body_mass[bodies]
    ipos = rep.xpos[:, bodies] + np.einsum("tbij,bj->tbi", rep.xmat[:, bodies], model.body_ipos[bodies])
    return np.einsum("tbi,b->ti", ipos, mass) / mass.sum(), float(mass.sum())


@dataclass(frozen=True)
class Load:
    """What the zero-moment point asks of the ankles, per frame (T frames).

    Attributes:
        ratio: (T,) the largest |torque| / limit over the stance ankles' hinges.
        sustained: (T,) ``ratio`` averaged over ``WINDOW_S``.
        excess: (T, 2) how far (m, world XY) the zero-moment point must move to load every
            hinge at ``MARGIN`` of its motor at most.
        supported: (T,) a foot on the floor.
        height: mean height (m) of the centre of mass.
        foot_low: side -> (T,) the lowest point (m) of that foot's geoms.
    """

    ratio: np.ndarray
    sustained: np.ndarray
    excess: np.ndarray
    supported: np.ndarray
    height: float
    foot_low: dict[str, np.ndarray]


def ankle_load(robot: RobotModel, ankles: Ankles, rep: Replay, fps: float) -> Load:
    """The load of the cart-table zero-moment point on the ankles (see the module)."""
    model = robot.model
    com, mass = centre_of_mass(robot, rep)
    t_len = len(com)
    acc = np.zeros_like(com)
    if t_len > 2:
        acc[1:-1] = (com[2:] - 2 * com[1:-1] + com[:-2]) * fps**2
    height = float(com[:, 2].mean())
    zmp = com[:, :2] - (com[:, 2:3] / G) * acc[:, :2]
    feet = set(robot.feet["left"].geoms) | set(robot.feet["right"].geoms)
    root = model.body_rootid[robot.tree.node_body[0]]
    others = [
        g
        for g in range(model.ngeom)
        if model.geom_contype[g] | model.geom_conaffinity[g]
        and model.body_rootid[model.geom_bodyid[g]] == root
        and g not in feet
    ]
    # A knee, a hand or the seat on the floor takes weight the model does not place.
    body_down = (
        geom_lowest_z(model, rep, others).min(axis=1) < SUPPORT_HEIGHT if others else np.zeros(t_len, bool)
    )
    down, anchor, axis, sole, foot_low = {}, {}, {}, {}, {}
    for side in ("left", "right"):
        foot = robot.feet[side]
        geoms = list(foot.geoms)
        low = geom_lowest_z(model, rep, geoms).min(axis=1) if geoms else np.full(t_len, np.inf)
        foot_low[side] = low
        down[side] = low < SUPPORT_HEIGHT
        j = ankles.joints[side]
        b = model.jnt_bodyid[j]
        anchor[side] = rep.xpos[:, b] + np.einsum("tjab,jb->tja", rep.xmat[:, b], model.jnt_pos[j])
        axis[side] = np.einsum("tjab,jb->tja", rep.xmat[:, b], model.jnt_axis[j])
        node = int(robot.tree.node_body[foot.node])
        points = rep.xpos[:, node, None] + np.einsum("tab,pb->tpa", rep.xmat[:, node], foot.points)
        sole[side] = points[..., :2]
    ratio = np.zeros(t_len)
    excess = np.zeros((t_len, 2))
    weight = mass * G
    on = {s: down[s] & ~body_down for s in ("left", "right")}
    count = on["left"].astype(np.float64) + on["right"]
    both = on["left"] & on["right"]
    apart = anchor["right"][:, 0, :2] - anchor["left"][:, 0, :2]
    apart /= np.maximum(np.linalg.norm(apart, axis=1, keepdims=True), 1e-9)
    for k in range(min(len(ankles.joints["left"]), len(ankles.joints["right"]))):
        share = {s: (on[s] / np.maximum(count, 1.0))[:, None] for s in on}  # (T, 1)
        origin = sum(share[s] * anchor[s][:, k, :2] for s in on)  # (T, 2)
        ax = sum(share[s] * axis[s][:, k] for s in on)  # (T, 3)
        limit = sum(on[s] * float(ankles.limits[s][k]) for s in on)  # (T,)
        lever = np.stack([ax[:, 1], -ax[:, 0]], axis=1)  # ((p - o) x z) . axis = lever . (p - o)
        n = np.linalg.norm(lever, axis=1)
        u = lever / np.maximum(n, 1e-9)[:, None]
        # Double support holds a moment along the line between the feet by itself.
        use = (count > 0) & (n > 1e-6) & np.isfinite(limit) & (limit > 0)
        use &= ~(both & (np.abs(np.sum(u * apart, axis=1)) > APART))
        arm = np.sum(u * (zmp - origin), axis=1) * n
        # Beyond the soles the weight cannot bear: the rest is a residual, not torque.
        reach = {s: np.einsum("tpi,ti->tp", sole[s] - origin[:, None], u) for s in on}
        lo = np.minimum.reduce([np.where(on[s][:, None], reach[s], np.inf).min(axis=1) for s in on])
        hi = np.maximum.reduce([np.where(on[s][:, None], reach[s], -np.inf).max(axis=1) for s in on])
        borne = np.clip(arm, np.minimum(lo, 0.0) * n, np.maximum(hi, 0.0) * n)
        safe_limit = np.where(use, limit, 1.0)
        ratio = np.maximum(ratio, np.where(use, np.abs(borne) * weight / safe_limit, 0.0))
        over = np.where(use, np.abs(arm) - MARGIN * safe_limit / weight, 0.0)
        step = np.where(over > 0, -np.sign(arm) * over / np.maximum(n, 1e-9), 0.0)
        excess += step[:, None] * u
    frames = max(1, int(round(WINDOW_S * fps)) | 1)
    sustained = uniform_filter1d(ratio, size=frames, mode="constant") if t_len > 1 else ratio.copy()
    supported = down["left"] | down["right"]
    return Load(ratio, sustained, excess, supported, height, foot_low)


def floor_slide(robot: RobotModel, rep: Replay, load: Load) -> float:
    """Largest horizontal step (m) between two replayed frames of a foot's slowest sole point
    while the foot is within ``STANCE_HEIGHT`` of the floor in both (``load``: those frames'
    :func:`ankle_load`, with the feet's lowest points), whatever the human's foot does."""
    worst = 0.0
    for side in ("left", "right"):
        down = load.foot_low[side] < STANCE_HEIGHT
        both = down[1:] & down[:-1]
        if both.any():
            worst = max(worst, float(foot_steps(robot, rep, side)[both].max()))
    return worst


def balance_shift(robot: RobotModel, load: Load, fps: float, above: float = TRIGGER) -> np.ndarray | None:
    """(T, 2) world XY shift (m) of the centre of mass that moves the zero-moment point by
    the load's excess (least squares over the clip, see the module); None when the
    sustained load is within ``above``."""
    if load.sustained.size == 0 or float(load.sustained.max()) <= above:
        return None
    t_len = len(load.ratio)
    w = load.supported.astype(np.float64) * (np.linalg.norm(load.excess, axis=1) > 0)
    if t_len < 3 or not w.any():
        return None
    inner = np.ones(t_len - 2)
    second = (
        sp.diags(
            [np.r_[inner, 0.0], np.r_[0.0, -2.0 * inner, 0.0], np.r_[0.0, inner]],
            [-1, 0, 1],
            shape=(t_len, t_len),
        )
        * fps**2
    )  # rows 0 and T-1 empty: the ends are not accelerated
    a = sp.identity(t_len) - (load.height / G) * second
    weights = sp.diags(np.maximum(w, 1e-3))  # unsupported frames: follow the model loosely
    target = load.excess * w[:, None]
    h = (a.T @ weights @ a + RIDGE * sp.identity(t_len)).tocsc()
    shift = np.stack([spsolve(h, a.T @ (weights @ target[:, i])) for i in range(2)], axis=1)
    most = MAX_SHIFT * robot.scale
    size = np.linalg.norm(shift, axis=1, keepdims=True)
    return np.asarray(shift * np.minimum(1.0, most / np.maximum(size, 1e-12)))


HELD = ("left_ankle", "right_ankle", "left_foot", "right_foot")
"""Human joints a balance shift leaves in place (the footholds)."""
HALF = ("left_knee", "right_knee")
"""Human joints a balance shift moves by half."""


def shift_human(
    joints: np.ndarray, fps: float, shift: np.ndarray, shift_fps: float, transform: HumanToWorld
) -> np.ndarray:
    """The human's joints (T, 22, 3; metres, Y up, at ``fps``) with the body moved by the world
    XY ``shift`` (T_s, 2; metres, at ``shift_fps``), the feet left in place and the knees moved
    by half."""
    out = np.array(joints, dtype=np.float64, copy=True)
    times = np.arange(len(out)) / fps
    grid = np.arange(len(shift)) / shift_fps
    world = np.zeros((len(out), 3))
    for i in range(2):
        world[:, i] = np.interp(times, grid, shift[:, i])
    human = world @ transform.rotation / transform.scale  # a world vector in the human frame
    share = np.ones(out.shape[1])
    share[[JOINT_INDEX[j] for j in HELD]] = 0.0
    share[[JOINT_INDEX[j] for j in HALF]] = 0.5
    out += share[None, :, None] * human[:, None, :]
    return out
