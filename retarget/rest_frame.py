"""The rest frame of a humanoid MJCF: the floating base's orientation that stands it facing +X.

The retargeter reads a robot in its rest pose (``qpos0``) in MuJoCo's convention: +Z up, the
robot facing +X, its left +Y. Most MJCFs are written that way with the floating base at
identity. Others orient their root body in the file (the dm_control CMU humanoid's
``euler="90 0 0"``: its body frames are Y up, and it faces -Y), or lay the whole robot along
another axis (SMPL humanoids of physics-based character work are written Y up, lying on the
MuJoCo floor until their simulator turns them). The rest orientation is the MJCF's own root
orientation (``qpos0``), turned to stand the robot up and then about +Z by a multiple of 90
degrees to face +X, all read from the geometry, never from names:

1. **Up**: among the six world axes, those along which the lowest collision geoms lie on two
   separate chains, level with each other, whose common ancestor is well above them (two feet:
   along an arm, one hand is the extreme; upside down, the head); of those, the one along
   which the robot's centre of mass stands highest above them, if at least ``STAND_SHARE``
   of the robot's largest extent. +Z for a standing robot.
2. **Facing**: across the line between the two feet, towards where the soles reach beyond
   the ankles (toes are longer than heels). Where the toes do not say (less than
   ``MIN_TOE_REACH``), the file's facing is kept.
"""

from __future__ import annotations

import mujoco
import numpy as np

from retarget.geoms import aabb_corners, collision_geoms
from retarget.kinematics import axes_centre, quat_to_mat
from retarget.robot_files import ancestors, jointed_link

QUARTER_TURN = np.pi / 2
"""Facing is rounded to a multiple of this (rad): a foot's toe-out or asymmetric toes never
turn a robot written facing +X."""
LEG_SPLIT = 0.25
"""The two feet's common ancestor must be this fraction of the robot's height above its
lowest point (two toes on one foot are not two legs)."""
FEET_LEVEL = 0.05
"""The two feet's lowest points lie within this fraction of the root's height of each other."""
ANKLE_BAND = 0.15
"""A leg's ankle is its highest body whose origin is this fraction of the robot's height (or
less) above the floor."""
SOLE_BAND = 0.02
"""Collision geoms whose lowest point is this close (m) to the robot's lowest are its soles."""
ANKLE_AXES_BAND = 0.225
"""An ankle's parent link's hinge counts towards where the ankle turns when its anchor is this
fraction of the robot's height (or less) above the floor (a knee is about half)..."""
ANKLE_AXES_CROSS = 0.05
"""...or when its axis passes within this fraction of the robot's height of one of the ankle
link's own hinge axes (an ankle's pitch and roll cross; a knee's axis passes a shin's length
from the ankle's roll axis): HighTorque's Pi+ turns its ankle 8.5 cm above its soles, past
the band of its 35 cm."""
STAND_SHARE = 0.25
"""The robot's centre of mass stands at least this fraction of its largest extent above the two
feet along an axis for that axis to be its up (a humanoid's: about half its height); lower,
the "feet" are something else at the end of a short axis (the two hips of a robot lying on its
back), and the file's own orientation is kept."""
MIN_TOE_REACH = 0.01
"""Below this (m) the feet's geometry does not say which way they point: the MJCF's facing
is kept."""
HALF_TURN_REACH = 0.02
"""Turning a robot written with its feet side by side along Y round (facing -X) needs its
toes to say so by this much (m)."""
_UP = np.array([0.0, 0.0, 1.0])
_HINGE = mujoco.mjtJoint.mjJNT_HINGE
_AXES = np.concatenate([np.eye(3), -np.eye(3)])
"""The six world axes a file may stand its robot along."""


def _collision_geoms(model: mujoco.MjModel, root: int) -> list[int]:
    return [
        g
        for g in range(model.ngeom)
        if model.body_rootid[model.geom_bodyid[g]] == root
        and (model.geom_contype[g] or model.geom_conaffinity[g])
        and model.geom_type[g] not in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD)
    ]


def _lowest(model: mujoco.MjModel, data: mujoco.MjData, g: int, up: np.ndarray) -> tuple[float, np.ndarray]:
    """(lowest height along the axis ``up``, (3,) centre) of geom ``g``'s bounding box (MuJoCo's
    ``geom_aabb``) in the world."""
    rot = data.geom_xmat[g].reshape(3, 3)
    centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
    half = np.abs(rot) @ model.geom_aabb[g, 3:]
    return float(centre @ up - half @ np.abs(up)), centre


def _mass_centre(model: mujoco.MjModel, data: mujoco.MjData, root: int) -> np.ndarray:
    """(3,) the centre of mass of the robot rooted at body ``root`` (its root body's origin if
    it has no mass). The robot's height is read from it, not from the root's origin: a file
    may put its floating base's origin anywhere (Berkeley Humanoid Lite's is on the floor,
    below its soles)."""
    bodies = np.flatnonzero(model.body_rootid == root)
    mass = model.body_mass[bodies]
    if mass.sum() <= 0:
        return np.array(data.xpos[root])
    return np.asarray(mass @ data.xipos[bodies] / mass.sum())


def _extent(model: mujoco.MjModel, data: mujoco.MjData, root: int, axis: np.ndarray) -> float:
    """Length (m) of the robot's collision geometry along ``axis``."""
    geoms = _collision_geoms(model, root)
    if not geoms:
        return 0.0
    low = min(_lowest(model, data, g, axis)[0] for g in geoms)
    return -min(_lowest(model, data, g, -axis)[0] for g in geoms) - low


def _split_height(
    model: mujoco.MjModel, data: mujoco.MjData, common: int, feet: tuple[int, int], up: np.ndarray
) -> float:
    """Height along ``up`` at which the chains of two ``feet`` bodies part below their common
    ancestor ``common``: its origin, or where both of its children on those chains start if
    higher (a floating base whose origin is on the floor, Berkeley Humanoid Lite's, parts its
    legs at the hips above it)."""
    starts = []
    for foot in feet:
        chain = ancestors(model, foot)
        starts.append(float(data.xpos[chain[chain.index(common) - 1]] @ up))
    return max(float(data.xpos[common] @ up), min(starts))


def _two_feet(
    model: mujoco.MjModel, data: mujoco.MjData, root: int, up: np.ndarray
) -> tuple[int, int, float] | None:
    """(the bodies of the lowest collision geoms along ``up`` on two separate legs, the
    robot's centre of mass's height above them), or None."""
    low = sorted((_lowest(model, data, g, up)[0], g) for g in _collision_geoms(model, root))
    if len(low) < 2:
        return None
    floor = low[0][0]
    height = float(_mass_centre(model, data, root) @ up) - floor
    if height <= 0:
        return None
    first = int(model.geom_bodyid[low[0][1]])
    above = ancestors(model, first)
    for z, g in low[1:]:
        if z - floor > FEET_LEVEL * height:
            return None
        other = int(model.geom_bodyid[g])
        chain = ancestors(model, other)
        if other in above or first in chain:
            continue  # one chain (a toe below its foot)
        common = next(b for b in chain if b in above)
        if _split_height(model, data, common, (first, other), up) - floor > LEG_SPLIT * height:
            return first, other, height
    return None


def _axes_gap(data: mujoco.MjData, j: int, k: int) -> float:
    """The distance (m) between the axis lines of hinges ``j`` and ``k`` (inf where parallel)."""
    normal = np.cross(data.xaxis[j], data.xaxis[k])
    size = float(np.linalg.norm(normal))
    if size < 1e-3:
        return float("inf")
    return abs(float((data.xanchor[k] - data.xanchor[j]) @ normal)) / size


def _ankle_centre(
    model: mujoco.MjModel, data: mujoco.MjData, ankle: int, floor: float, height: float
) -> np.ndarray:
    """(3,) where a leg's ankle turns: the point nearest the axes of the ankle link's hinges and
    of its parent link's that cross them (ANKLE_AXES_CROSS) or lie within ANKLE_AXES_BAND of
    the robot's height above the floor (an ankle's pitch and roll; a URDF may put the roll
    link's origin anywhere along the roll axis: THORMANG3's 5.7 cm ahead of the ankle); the
    link's origin without one."""
    parent = jointed_link(model, int(model.body_parentid[ankle]))
    own = [j for j in range(model.njnt) if model.jnt_bodyid[j] == ankle and model.jnt_type[j] == _HINGE]
    if not own:
        return np.array(data.xpos[ankle])
    joints = list(own)
    for j in range(model.njnt):
        if model.jnt_bodyid[j] != parent or model.jnt_type[j] != _HINGE:
            continue
        low = data.xanchor[j][2] - floor <= ANKLE_AXES_BAND * height
        crossing = any(_axes_gap(data, j, k) <= ANKLE_AXES_CROSS * height for k in own)
        if (low or crossing) and all(abs(float(data.xaxis[j] @ data.xaxis[k])) < 1.0 - 1e-3 for k in own):
            joints.append(j)
    return axes_centre(data.xanchor[joints], data.xaxis[joints])


def _toe_reach(
    model: mujoco.MjModel, data: mujoco.MjData, foot: int, floor: float, height: float, direction: np.ndarray
) -> float:
    """How far (m) along ``direction`` the middle of the sole of ``foot``'s leg (the extent of
    its collision geoms within SOLE_BAND of the floor) lies beyond the ankle
    (:func:`_ankle_centre` of the leg's highest body whose origin is within ANKLE_BAND of the
    robot's height above the floor; at least the foot's own link, so that collision geoms in
    bodies welded below it, a foot's cleats, count together). The middle of the sole's extent,
    not the mean of its geoms' centres: a shell around the ankle that comes near the floor too
    (iCub's) does not pull the sole back under the ankle."""
    ankle = jointed_link(model, foot)
    for b in ancestors(model, ankle):
        if data.xpos[b][2] - floor > ANKLE_BAND * height:
            break
        ankle = b
    below = [b for b in range(1, model.nbody) if ankle in ancestors(model, b)]
    sole = [
        data.xpos[b] + aabb_corners(model, g) @ data.xmat[b].reshape(3, 3).T
        for b in below
        for g in collision_geoms(model, b)
        if _lowest(model, data, g, _UP)[0] - floor < SOLE_BAND
    ]
    if not sole:
        return 0.0
    along = np.concatenate(sole) @ direction
    return float(
        (along.min() + along.max()) / 2 - _ankle_centre(model, data, ankle, floor, height) @ direction
    )


def _turn(quat: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``quat`` (wxyz) turned by ``angle`` (rad) about the world ``axis``."""
    out = np.empty(4)
    turn = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)])
    mujoco.mju_mulQuat(out, turn, quat)
    return out


def _written_quat(model: mujoco.MjModel, root: int) -> tuple[int, np.ndarray]:
    """(qpos address of the free joint of body ``root``, (4,) wxyz its ``qpos0`` orientation,
    normalised)."""
    free = next(j for j in range(model.njnt) if model.jnt_bodyid[j] == root)
    adr = int(model.jnt_qposadr[free])
    quat = np.array(model.qpos0[adr + 3 : adr + 7], dtype=float)
    return adr, quat / max(float(np.linalg.norm(quat)), 1e-12)


def rest_root_quat(model: mujoco.MjModel, root: int) -> np.ndarray:
    """(4,) wxyz: the floating base ``root``'s rest orientation (see the module docstring).

    The MJCF's own ``qpos0`` orientation where its feet do not say how it stands or faces.
    """
    adr, quat = _written_quat(model, root)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    size = max(_extent(model, data, root, u) for u in np.eye(3))
    stands = [
        (f[2], i)
        for i, u in enumerate(_AXES)
        if (f := _two_feet(model, data, root, u)) and f[2] >= STAND_SHARE * size
    ]
    if not stands:
        return quat
    up = _AXES[max(stands)[1]]
    if up[2] != 1.0:  # laid down (a quarter turn) or upside down (a half turn) in the file
        if up[2] == 0.0:
            quat = _turn(quat, np.cross(up, _UP), QUARTER_TURN)
        else:
            quat = _turn(quat, np.array([1.0, 0.0, 0.0]), 2 * QUARTER_TURN)
        data.qpos[adr + 3 : adr + 7] = quat
        mujoco.mj_kinematics(model, data)
    feet = _two_feet(model, data, root, _UP)
    if feet is None:
        return quat
    across = data.xpos[feet[1]] - data.xpos[feet[0]]
    across[2] = 0.0
    if np.linalg.norm(across) < 1e-6:
        return quat
    forward = np.cross(across / np.linalg.norm(across), _UP)
    floor = float(_mass_centre(model, data, root)[2]) - feet[2]
    reach = sum(_toe_reach(model, data, f, floor, feet[2], forward) for f in feet[:2]) / 2
    if abs(reach) < MIN_TOE_REACH:
        return quat
    if reach < 0:
        forward = -forward
    quarters = round(float(np.arctan2(forward[1], forward[0])) / QUARTER_TURN)
    if quarters == 0 or (abs(quarters) == 2 and abs(reach) < HALF_TURN_REACH):
        return quat
    return _turn(quat, _UP, -QUARTER_TURN * quarters)


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "-") + "XYZ"[i]


def rest_turn_note(model: mujoco.MjModel, root: int) -> str | None:
    """One line saying how the rest frame turns the file's robot (None where it stands as
    written: up +Z, facing +X): along which of the file's world axes it stands and which way it
    faces, as read from its feet (for a user reviewing an inferred mapping)."""
    written = quat_to_mat(_written_quat(model, root)[1])
    turn = quat_to_mat(rest_root_quat(model, root)) @ written.T  # world turn from the file to the rest
    if np.allclose(turn, np.eye(3), atol=1e-6):
        return None
    up, forward = turn.T @ _UP, turn.T @ np.array([1.0, 0.0, 0.0])
    return (
        f"rest frame: the file's robot stands along its world {_axis_name(up)} axis and faces "
        f"{_axis_name(forward)} (read from its feet); it is turned to stand up along +Z facing +X"
    )
