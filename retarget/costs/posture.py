"""Posture prior: ``sum_j w_j (l_posture (q_j - q_rest_j))^2``.

Pulls every joint toward the rest pose with the mapping's per-joint weights; ``l_posture``
(m/rad) makes an angle comparable with a distance. It settles the joints the targets leave
free (wrist rolls, waist) and keeps the normal equations well conditioned.
"""

from __future__ import annotations

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.robot_model import RobotModel


class PostureCost(CostTerm[TermValue]):
    """Weighted squared joint deviations from the rest pose (a constant diagonal Hessian)."""

    name = "posture"

    def __init__(self, robot: RobotModel, l_posture: float) -> None:
        self.weight = robot.posture_weights * l_posture**2  # (nj,)
        self.rest = robot.rest_q  # (nj,)

    def evaluate(self, cfg: Configuration) -> TermValue:
        return TermValue(np.sum(self.weight * (cfg.q - self.rest) ** 2, axis=1))

    def linearise(self, cfg: Configuration, value: TermValue, eq: NormalEquations) -> None:
        j = 6 + np.arange(len(self.weight))
        eq.h[:, j, j] += self.weight
        eq.g[:, 6:] += self.weight * (cfg.q - self.rest)
