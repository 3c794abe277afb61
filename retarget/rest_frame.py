"""The rest frame of a humanoid MJCF: the floating base's orientation that stands it facing +X.

The retargeter reads a robot in its rest pose (``qpos0``) in MuJoCo's convention: +Z up, the
robot facing +X, its left +Y. Most MJCFs are written that way with the floating base at
identity; others orient their root body in the file (the dm_control CMU humanoid's
``euler="90 0 0"``: its body frames are Y up) or face another way (-Y). The rest orientation
is the MJCF's own root orientation (``qpos0``, which stands the robot up) turned about +Z by a
multiple of 90 degrees so that the robot faces +X. Facing is read from the geometry, never
from names: the two feet are the bodies owning the lowest collision geoms on two separate
chains (their common ancestor well above the floor); the robot faces across the line between
them, towards where the soles reach beyond the ankles (toes are longer than heels).
"""

from __future__ import annotations

import mujoco
import numpy as np

from retarget.robot_files import ancestors

QUARTER_TURN = np.pi / 2
"""Facing is rounded to a multiple of this (rad): a foot's toe-out or asymmetric toes never
turn a robot written facing +X."""
LEG_SPLIT = 0.25
"""The two feet's common ancestor must be this fraction of the robot's height above its
lowest point (two toes on one foot are not two legs)."""
ANKLE_BAND = 0.15
"""A leg's ankle is its highest body whose origin is this fraction of the robot's height (or
less) above the floor."""
SOLE_BAND = 0.02
"""Collision geoms whose lowest point is this close (m) to the robot's lowest are its soles."""
MIN_TOE_REACH = 0.01
"""Below this (m) the feet's geometry does not say which way they point: the MJCF's facing
is kept."""
HALF_TURN_REACH = 0.02
"""Turning a robot written with its feet side by side along Y round (facing -X) needs its
toes to say so by this much (m)."""


def _lowest(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[float, np.ndarray]:
    """(lowest z, (3,) centre) of geom ``g``'s bounding box (MuJoCo's ``geom_aabb``) in the world."""
    rot = data.geom_xmat[g].reshape(3, 3)
    centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
    half = np.abs(rot) @ model.geom_aabb[g, 3:]
    return float(centre[2] - half[2]), centre


def _two_feet(model: mujoco.MjModel, data: mujoco.MjData, root: int) -> tuple[int, int] | None:
    """The bodies of the lowest collision geoms on two separate legs, or None."""
    geoms = [
        g
        for g in range(model.ngeom)
        if model.body_rootid[model.geom_bodyid[g]] == root
        and (model.geom_contype[g] or model.geom_conaffinity[g])
        and model.geom_type[g] not in (mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD)
    ]
    if len(geoms) < 2:
        return None
    low = sorted((_lowest(model, data, g)[0], g) for g in geoms)
    bodies = [b for b in range(1, model.nbody) if model.body_rootid[b] == root]
    floor = low[0][0]
    height = max(float(data.xpos[bodies, 2].max()) - floor, 1e-3)
    first = int(model.geom_bodyid[low[0][1]])
    above = ancestors(model, first)
    for _, g in low[1:]:
        other = int(model.geom_bodyid[g])
        chain = ancestors(model, other)
        if other in above or first in chain:
            continue  # one chain (a toe below its foot)
        common = next(b for b in chain if b in above)
        if data.xpos[common][2] - floor > LEG_SPLIT * height:
            return first, other
    return None


def _toe_reach(
    model: mujoco.MjModel, data: mujoco.MjData, foot: int, floor: float, height: float, direction: np.ndarray
) -> float:
    """How far (m) along ``direction`` the sole of ``foot``'s leg (its collision geoms within
    SOLE_BAND of the floor) reaches beyond the ankle (the highest body of the leg whose origin
    is within ANKLE_BAND of the robot's height above the floor)."""
    ankle = foot
    for b in ancestors(model, foot):
        if data.xpos[b][2] - floor > ANKLE_BAND * height:
            break
        ankle = b
    below = [b for b in range(1, model.nbody) if ankle in ancestors(model, b)]
    sole = [
        centre
        for g in range(model.ngeom)
        if model.geom_bodyid[g] in below and (model.geom_contype[g] or model.geom_conaffinity[g])
        for low, centre in [_lowest(model, data, g)]
        if low - floor < SOLE_BAND
    ]
    if not sole:
        return 0.0
    return float(np.mean((np.array(sole) - data.xpos[ankle]) @ direction))


def _yaw_quat(angle: float) -> np.ndarray:
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


def rest_root_quat(model: mujoco.MjModel, root: int) -> np.ndarray:
    """(4,) wxyz: the floating base ``root``'s rest orientation (see the module docstring).

    The MJCF's own ``qpos0`` orientation where its feet do not say which way it faces.
    """
    free = next(j for j in range(model.njnt) if model.jnt_bodyid[j] == root)
    adr = int(model.jnt_qposadr[free])
    own = np.array(model.qpos0[adr + 3 : adr + 7], dtype=float)
    own /= max(float(np.linalg.norm(own)), 1e-12)
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    feet = _two_feet(model, data, root)
    if feet is None:
        return own
    across = data.xpos[feet[1]] - data.xpos[feet[0]]
    across[2] = 0.0
    if np.linalg.norm(across) < 1e-6:
        return own
    forward = np.cross(across / np.linalg.norm(across), [0.0, 0.0, 1.0])
    bodies = [b for b in range(1, model.nbody) if model.body_rootid[b] == root]
    floor = min(_lowest(model, data, g)[0] for g in range(model.ngeom) if model.geom_bodyid[g] in bodies)
    height = max(float(data.xpos[bodies, 2].max()) - floor, 1e-3)
    reach = sum(_toe_reach(model, data, f, floor, height, forward) for f in feet) / 2
    if abs(reach) < MIN_TOE_REACH:
        return own
    if reach < 0:
        forward = -forward
    quarters = round(float(np.arctan2(forward[1], forward[0])) / QUARTER_TURN)
    if quarters == 0 or (abs(quarters) == 2 and abs(reach) < HALF_TURN_REACH):
        return own
    turn = -QUARTER_TURN * quarters
    out = np.empty(4)
    mujoco.mju_mulQuat(out, _yaw_quat(turn), own)
    return out
