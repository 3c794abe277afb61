"""The robots at a glance: name, model file, joints, standing height and scale.

``robot_catalog()`` lists the packaged robots (``controlmm robots`` prints it);
``describe_robot(robot)`` describes any robot argument (a packaged name, a humanoid MJCF or
a mapping ``.json``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from retarget.geoms import aabb_corners
from retarget.mapping import packaged_mappings
from retarget.robot_model import RobotModel, load_robot
from retarget.robots import PACKAGED_ROBOTS, available_robots


@dataclass(frozen=True)
class RobotInfo:
    """One robot: ``name``; ``mjcf`` (path); ``dof`` (hinge and slide joints); ``height`` (m,
    standing in the rest pose: highest geom point above the soles); ``scale`` (human -> robot);
    ``mapping`` (where the mapping came from); ``keypoints`` (mapped human joints); ``arms``
    (whether the arms are mapped)."""

    name: str
    mjcf: Path
    dof: int
    height: float
    scale: float
    mapping: str
    keypoints: int
    arms: bool


def standing_height(robot: RobotModel) -> float:
    """Highest point (m) of the robot's geoms (their bounding boxes) above its soles in the rest pose."""
    m = robot.model
    data = mujoco.MjData(m)
    data.qpos[:] = m.qpos0
    data.qpos[3:7] = robot.rest_root_quat
    data.qpos[:3] = 0.0
    mujoco.mj_kinematics(m, data)
    root = int(robot.tree.node_body[0])
    top = -np.inf
    for g in range(m.ngeom):
        body = int(m.geom_bodyid[g])
        if m.body_rootid[body] != m.body_rootid[root]:
            continue
        world = data.xpos[body] + aabb_corners(m, g) @ data.xmat[body].reshape(3, 3).T
        top = max(top, float(world[:, 2].max()))
    return top - robot.floor_z


def describe_robot(robot: str | Path | RobotModel) -> RobotInfo:
    """A :class:`RobotInfo` for a robot argument or a loaded :class:`RobotModel`."""
    rm = load_robot(robot)
    return RobotInfo(
        name=rm.name,
        mjcf=rm.mjcf,
        dof=len(rm.tree.joint_names),
        height=standing_height(rm),
        scale=float(rm.scale),
        mapping=rm.mapping.source,
        keypoints=len(rm.keypoint_names),
        arms=rm.has_keypoint("left_wrist") and rm.has_keypoint("right_wrist"),
    )


def robot_catalog() -> list[RobotInfo]:
    """The packaged robots whose MJCF is installed and whose mapping is shipped, in package order."""
    have = set(available_robots()) & set(packaged_mappings())
    return [describe_robot(name) for name in PACKAGED_ROBOTS if name in have]
