"""Minimal worlds for checks without the scene library: a packaged robot on a plane floor.

``robot_world("g1", obstacles=[Obstacle(...)])`` (its spec: ``robot_spec``) compiles the Menagerie robot
(from ``retarget.robot_files.load_robot_spec``) into a world with a floor plane named ``floor`` and one
joint-less body per static obstacle (or a mocap body for moving ones), so that the qpos
layout equals the robot's. The real scene library lives in ``scenes``; this is for
``check_trajectory`` on a bare floor, for tests and for benchmarks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from controlmm.errors import ControlMMError
from retarget.robot_files import load_robot_spec
from sim.geometry import support_heights
from sim.world import make_world

_TYPES = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
}


@dataclass(frozen=True)
class Obstacle:
    """A primitive obstacle: MuJoCo ``type``/``size`` (half extents, radius, half length),
    world ``pos``, ``quat`` (wxyz); ``mocap=True`` puts it on a mocap body named ``name``."""

    name: str
    type: str
    size: tuple[float, ...]
    pos: tuple[float, float, float]
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    mocap: bool = False


def robot_world(robot: str = "g1", obstacles: Sequence[Obstacle] = (), floor: bool = True) -> mujoco.MjModel:
    """Compile ``robot`` (a packaged name, an MJCF path or a mapping .json) with a floor and obstacles."""
    return robot_spec(robot, obstacles, floor).compile()


def robot_spec(robot: str = "g1", obstacles: Sequence[Obstacle] = (), floor: bool = True) -> mujoco.MjSpec:
    """The ``mujoco.MjSpec`` of :func:`robot_world` (``make_world`` keeps it: the physics check
    saves the model from it)."""
    spec = load_robot_spec(robot)  # the robot's own spec: options and keyframes kept, colliders declared
    if floor:
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    for ob in obstacles:
        if ob.type not in _TYPES:
            raise ControlMMError(f"obstacle '{ob.name}' has type '{ob.type}'; allowed: {', '.join(_TYPES)}")
        size = list(ob.size) + [0.0] * (3 - len(ob.size))
        if ob.mocap:
            body = spec.worldbody.add_body(name=ob.name, mocap=True, pos=list(ob.pos), quat=list(ob.quat))
            body.add_geom(name=ob.name, type=_TYPES[ob.type], size=size)
        else:
            body = spec.worldbody.add_body(name=f"{ob.name}_body")
            body.add_geom(name=ob.name, type=_TYPES[ob.type], size=size, pos=list(ob.pos), quat=list(ob.quat))
    return spec


def standing_qpos(model: mujoco.MjModel) -> np.ndarray:
    """A standing pose (nq,): the model's ``stand``/``home`` keyframe, else qpos0 lowered or
    raised so that the lowest robot collision point touches z = 0."""
    for name in ("stand", "home"):
        key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, name)
        if key >= 0:
            return np.array(model.key_qpos[key])
    world = make_world(model)
    q = np.array(model.qpos0)
    adr = world.root_qpos_adr
    q[adr + 3 : adr + 7] = (1.0, 0.0, 0.0, 0.0)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    low = support_heights(
        model,
        world.robot_geoms,
        data.geom_xpos[world.robot_geoms][None],
        data.geom_xmat[world.robot_geoms][None],
        np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]),
        world.hull_vertices,
    )
    q[adr + 2] -= float(np.nanmin(low))
    return q
