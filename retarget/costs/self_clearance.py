"""Self-clearance: ``w_self sum_pairs min(0, d - margin)^2`` over the robot's capsule pairs.

The arms keep clear of the trunk, the legs and each other, the legs of each other
(:mod:`retarget.selfcollision`): ``d`` is the signed distance of two capsules enclosing
collision geoms, ``margin`` the distance each pair keeps free. Only pairs closer than their
margin have a residual (sparse rows).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, SparseRows, TermValue
from retarget.selfcollision import ClosePairs, SelfClearance, close_pairs


@dataclass
class SelfClearanceValue(TermValue):
    """``close``: the (frame, pair) entries closer than their margin."""

    close: ClosePairs

    def select(self, use: np.ndarray, other: TermValue) -> SelfClearanceValue:
        assert isinstance(other, SelfClearanceValue)
        mine, theirs = use[self.close.frame], ~use[other.close.frame]
        close = ClosePairs(
            *(
                np.concatenate([getattr(self.close, f.name)[mine], getattr(other.close, f.name)[theirs]])
                for f in fields(ClosePairs)
            )
        )
        return SelfClearanceValue(np.where(use, self.cost, other.cost), close)


class SelfClearanceCost(CostTerm[SelfClearanceValue]):
    """Capsule pairs kept their margin apart (stiff)."""

    name = "self_clearance"

    def __init__(self, clearance: SelfClearance, weight: float) -> None:
        self.clearance = clearance
        self.weight = weight

    def evaluate(self, cfg: Configuration) -> SelfClearanceValue:
        close = close_pairs(cfg.poses, self.clearance)
        cost = np.zeros(len(cfg.q))
        np.add.at(cost, close.frame, self.weight * (close.dist - self.clearance.margin[close.pair]) ** 2)
        return SelfClearanceValue(cost, close)

    def linearise(self, cfg: Configuration, value: SelfClearanceValue, eq: NormalEquations) -> None:
        """d(d)/dx = u . (J(pa) - J(pb)), u the unit vector from the closest point pb to pa."""
        close, sc = value.close, self.clearance
        if not close.frame.size:
            return
        u = close.pa - close.pb
        norm = np.linalg.norm(u, axis=1, keepdims=True)
        u = np.where(norm > 1e-9, u / np.maximum(norm, 1e-9), np.array([0.0, 0.0, 1.0]))
        tree = cfg.robot.tree
        ja = tree.directional_jacobian(cfg.poses, close.frame, sc.node[sc.first[close.pair]], close.pa, u)
        jb = tree.directional_jacobian(cfg.poses, close.frame, sc.node[sc.second[close.pair]], close.pb, u)
        root = np.sqrt(self.weight)
        eq.rows.append(SparseRows(close.frame, root * (ja - jb), root * (close.dist - sc.margin[close.pair])))

    def violation(self, cfg: Configuration, value: SelfClearanceValue) -> np.ndarray | None:
        """Overlap (m) of the deepest capsule pair per frame (0: none overlaps)."""
        if not value.close.frame.size:
            return None
        worst = np.zeros(len(cfg.q))
        np.maximum.at(worst, value.close.frame, -value.close.dist)
        return worst
