"""Every body above the floor: ``w sum_bodies min(0, z_lowest - clearance)^2`` (metres).

Kneeling puts a knee on the floor, a deep squat brings shins and hands near it: each non-foot
body's lowest support point (:mod:`retarget.bodyfloor`) keeps ``clearance`` above z = 0. One
residual per body and frame, active in few frames: its rows are sparse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.bodyfloor import BodyFloor, lowest_points
from retarget.costs.base import Configuration, CostTerm, NormalEquations, SparseRows, TermValue


@dataclass
class BodyFloorValue(TermValue):
    """``low``: (T, B) min(0, height of each body's lowest point - clearance) (m);
    ``point``: (T, B, 3) that lowest point (world)."""

    low: np.ndarray
    point: np.ndarray


class BodyFloorCost(CostTerm[BodyFloorValue]):
    """The non-foot bodies' lowest points kept ``clearance`` above the floor (stiff)."""

    name = "body_floor"

    def __init__(self, body_floor: BodyFloor, weight: float, clearance: float) -> None:
        self.body_floor = body_floor
        self.weight = weight
        self.clearance = clearance

    def evaluate(self, cfg: Configuration) -> BodyFloorValue:
        z, point = lowest_points(cfg.poses, self.body_floor, self.clearance)
        low = np.minimum(z - self.clearance, 0.0)
        return BodyFloorValue(self.weight * np.sum(low**2, axis=1), low, point)

    def linearise(self, cfg: Configuration, value: BodyFloorValue, eq: NormalEquations) -> None:
        fr, b = np.nonzero(value.low < 0)
        if not fr.size:
            return
        up = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (fr.size, 3))
        jac = cfg.robot.tree.directional_jacobian(
            cfg.poses, fr, self.body_floor.node[b], value.point[fr, b], up
        )
        root = np.sqrt(self.weight)
        eq.rows.append(SparseRows(fr, root * jac, root * value.low[fr, b]))

    def violation(self, cfg: Configuration, value: BodyFloorValue) -> np.ndarray | None:
        """Depth (m) of each frame's lowest body point below the floor."""
        if not value.low.size:
            return None
        return -(value.low.min(axis=1) + self.clearance)
