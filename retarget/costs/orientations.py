"""Orientations: ``sum_o w_o(t) l_rot^2 |a_o * log(R_o(t) R*_o(t)^T)|^2``.

Pelvis, torso and feet follow the orientation of the human's frames; ``l_rot`` (m/rad) makes
an angle comparable with a distance, ``a_o`` weighs tilt and heading (the trunk's tilt
counts less than its heading).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.kinematics import so3_log
from retarget.robot_model import RobotModel
from retarget.targets import Targets


@dataclass
class OrientationValue(TermValue):
    """``res``: (T, O, 3) weighted rotation vectors of the orientation errors (m)."""

    res: np.ndarray


class OrientationCost(CostTerm[OrientationValue]):
    """Weighted squared world rotation errors of the oriented keypoints' nodes."""

    name = "orientations"

    def __init__(self, robot: RobotModel, targets: Targets, l_rot: float) -> None:
        self.nodes = robot.nodes[targets.ori_kp]  # (O,)
        self.target = targets.ori_rot  # (T, O, 3, 3)
        self.sqrt_weight = (
            np.sqrt(targets.ori_weight)[..., None] * l_rot * np.sqrt(targets.ori_axis_weight)[None]
        )  # (T, O, 3)

    def evaluate(self, cfg: Configuration) -> OrientationValue:
        err = so3_log(cfg.poses.rot[:, self.nodes] @ np.swapaxes(self.target, -1, -2))
        res = self.sqrt_weight * err
        return OrientationValue(np.sum(res**2, axis=(1, 2)), res)

    def linearise(self, cfg: Configuration, value: OrientationValue, eq: NormalEquations) -> None:
        t, n = eq.g.shape
        jac = cfg.robot.tree.rotation_jacobian(cfg.poses, self.nodes)  # (T, O, 3, n)
        jr = (self.sqrt_weight[..., None] * jac).reshape(t, -1, n)
        jrt = np.swapaxes(jr, 1, 2)
        eq.h += jrt @ jr
        eq.g += (jrt @ value.res.reshape(t, -1, 1))[..., 0]
