"""The retargeting solver's cost as a list of terms (:class:`~retarget.costs.base.CostTerm`).

The solver (:mod:`retarget.solver`) minimises the sum of the terms :func:`default_costs`
builds; a new term is one class in this package and one entry in that list. Weights come
from :class:`~retarget.solver_config.SolverConfig`.
"""

from __future__ import annotations

import numpy as np

from retarget.costs.acceleration import AccelerationCost
from retarget.costs.base import Configuration, CostTerm, NormalEquations, SparseRows, TermValue
from retarget.costs.body_floor import BodyFloorCost
from retarget.costs.coupling import CouplingCost
from retarget.costs.floor import FloorCost
from retarget.costs.keypoints import KeypointCost
from retarget.costs.orientations import OrientationCost
from retarget.costs.posture import PostureCost
from retarget.costs.segments import SegmentCost
from retarget.costs.self_clearance import MidpointClearanceCost, SelfClearanceCost
from retarget.costs.temporal import REFERENCE_FPS
from retarget.costs.velocity import VelocityCost
from retarget.robot_model import RobotModel
from retarget.solver_config import SolverConfig
from retarget.targets import Targets

__all__ = [
    "AccelerationCost",
    "BodyFloorCost",
    "Configuration",
    "CostTerm",
    "CouplingCost",
    "FloorCost",
    "KeypointCost",
    "MidpointClearanceCost",
    "NormalEquations",
    "OrientationCost",
    "PostureCost",
    "SegmentCost",
    "SelfClearanceCost",
    "SparseRows",
    "TermValue",
    "VelocityCost",
    "default_costs",
    "joint_speed_weights",
]


def joint_speed_weights(robot: RobotModel, config: SolverConfig) -> np.ndarray:
    """(nj,) the velocity term's weight per joint at 20 fps: ``w_vel_joint``, plus
    ``w_joint_damping`` on the squared share of the motor the joint's damping takes at its
    speed (``damping_share * dq * 20``: :attr:`RobotModel.damping_share`)."""
    return config.w_vel_joint + config.w_joint_damping * (REFERENCE_FPS * robot.damping_share) ** 2


def default_costs(
    robot: RobotModel, targets: Targets, config: SolverConfig, ref_x: np.ndarray, span: np.ndarray
) -> list[CostTerm]:
    """The solver's terms for ``targets`` (T frames).

    Args:
        robot, targets, config: the problem and its weights.
        ref_x: (T, n) reference of the temporal terms (:mod:`retarget.costs.temporal`).
        span: (T,) int, independent spans of frames (no temporal term couples two spans).
    """
    c = config
    terms: list[CostTerm] = [
        KeypointCost(targets),
        SegmentCost(targets),
        OrientationCost(robot, targets, c.l_rot),
        FloorCost(robot, targets, c.w_floor),
        PostureCost(robot, c.l_posture),
    ]
    if robot.couplings is not None:
        terms.append(CouplingCost(robot.couplings, c.w_coupling))
    if c.body_floor and robot.body_floor is not None:
        terms.append(BodyFloorCost(robot.body_floor, c.body_floor_weight, c.body_clearance))
    if c.self_clearance and robot.self_clearance is not None:
        terms.append(SelfClearanceCost(robot.self_clearance, c.w_self))
        if c.self_midpoints:
            terms.append(MidpointClearanceCost(robot.self_clearance, c.w_self, span))
    terms += [
        VelocityCost(
            ref_x, span, targets.fps, c.w_vel_root, joint_speed_weights(robot, c), targets.speed_gain
        ),
        AccelerationCost(ref_x, span, targets.fps, c.w_acc_root, c.w_acc_joint, c.exact_acceleration),
    ]
    return terms
