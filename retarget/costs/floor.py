"""Feet above the floor: ``w_floor sum_points min(0, z - radius - clearance(t))^2`` (metres).

Every collision point of both feet stays ``clearance(t)`` above z = 0: 1 mm in stance, 16 mm
in swing, ramping between them (:func:`retarget.targets.build_targets`). A one-sided
(hinge) residual: only points below their clearance count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.robot_model import RobotModel
from retarget.targets import Targets

SWING_CHECK = 0.005
"""Clearance (m) above which a foot counts as swinging for the violation check."""


@dataclass
class FloorValue(TermValue):
    """``points``: (T, P, 3) world foot points; ``active``: (T, P) below their clearance;
    ``res``: (T, P) sqrt(w_floor) * depth below the clearance (0 where inactive)."""

    points: np.ndarray
    active: np.ndarray
    res: np.ndarray


class FloorCost(CostTerm[FloorValue]):
    """The feet's collision points kept their clearance above the floor."""

    name = "floor"

    def __init__(self, robot: RobotModel, targets: Targets, weight: float) -> None:
        feet = [robot.feet["left"], robot.feet["right"]]
        self.nodes = np.concatenate([np.full(len(f.points), f.node) for f in feet])  # (P,)
        self.points = np.concatenate([f.points for f in feet])  # (P, 3) in the foot frames
        self.radius = np.concatenate([f.radius for f in feet])  # (P,)
        self.clearance = np.concatenate(
            [
                np.repeat(targets.clearance[side][:, None], len(f.points), axis=1)
                for side, f in zip(("left", "right"), feet, strict=True)
            ],
            axis=1,
        )  # (T, P)
        self.root_weight = np.sqrt(weight)

    def evaluate(self, cfg: Configuration) -> FloorValue:
        pts = cfg.robot.tree.points(cfg.poses, self.nodes, self.points)
        low = pts[..., 2] - self.radius - self.clearance
        active = low < 0
        res = self.root_weight * np.where(active, low, 0.0)
        return FloorValue(np.sum(res**2, axis=1), pts, active, res)

    def linearise(self, cfg: Configuration, value: FloorValue, eq: NormalEquations) -> None:
        if not value.active.any():
            return
        jf = cfg.robot.tree.point_jacobian(cfg.poses, self.nodes, value.points, rows=(2,))[:, :, 0]
        jf *= (self.root_weight * value.active)[..., None]
        jft = np.swapaxes(jf, 1, 2)
        eq.h += jft @ jf
        eq.g += (jft @ value.res[..., None])[..., 0]

    def violation(self, cfg: Configuration, value: FloorValue) -> np.ndarray | None:
        """Depth (m) of a swing foot below half its clearance (None: no foot swings)."""
        swing = self.clearance > SWING_CHECK
        if not swing.any():
            return None
        height = value.points[..., 2] - self.radius
        return np.max(np.where(swing, 0.5 * self.clearance - height, 0.0), axis=1)
