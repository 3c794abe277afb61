"""Self-clearance: ``w_self sum_pairs min(0, d - margin)^2`` over the robot's capsule pairs.

The arms keep clear of the trunk, the legs and each other, the legs of each other
(:mod:`retarget.selfcollision`): ``d`` is the signed distance of two capsules enclosing
collision geoms, ``margin`` the distance each pair keeps free. Only pairs closer than their
margin have a residual (sparse rows). :class:`MidpointClearanceCost` keeps the same pairs
apart halfway between consecutive frames (:mod:`retarget.midpoints`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TypeVar

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, SparseRows, TermValue
from retarget.costs.temporal import coupled_pairs
from retarget.midpoints import MidpointPairs, midpoint_pairs
from retarget.selfcollision import ClosePairs, SelfClearance, close_pairs

Entries = TypeVar("Entries", ClosePairs, MidpointPairs)


def _merge(use: np.ndarray, mine: Entries, theirs: Entries) -> Entries:
    """The entries of ``mine`` on the frames where ``use`` (T,) bool is true, those of
    ``theirs`` on the others (by each entry's frame)."""
    a, b = use[mine.frame], ~use[theirs.frame]
    merged = (np.concatenate([getattr(mine, f.name)[a], getattr(theirs, f.name)[b]]) for f in fields(mine))
    return type(mine)(*merged)


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (E, 3) normalised (+z where a row is zero)."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(norm > 1e-9, v / np.maximum(norm, 1e-9), np.array([0.0, 0.0, 1.0]))


@dataclass
class SelfClearanceValue(TermValue):
    """``close``: the (frame, pair) entries closer than their margin."""

    close: ClosePairs

    def select(self, use: np.ndarray, other: TermValue) -> SelfClearanceValue:
        assert isinstance(other, SelfClearanceValue)
        return SelfClearanceValue(np.where(use, self.cost, other.cost), _merge(use, self.close, other.close))


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
        u = _unit(close.pa - close.pb)
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


@dataclass
class MidpointClearanceValue(TermValue):
    """``close``: the (frame pair, capsule pair) entries closer than their limit halfway."""

    close: MidpointPairs

    def select(self, use: np.ndarray, other: TermValue) -> MidpointClearanceValue:
        """Whole spans only (the solver's span acceptance): an entry goes with its frame t."""
        assert isinstance(other, MidpointClearanceValue)
        close = _merge(use, self.close, other.close)
        return MidpointClearanceValue(np.where(use, self.cost, other.cost), close)


class MidpointClearanceCost(CostTerm[MidpointClearanceValue]):
    """Capsule pairs kept apart halfway between frames t and t + 1 of a span (stiff):
    ``w sum min(0, d_mid - limit)^2`` (:mod:`retarget.midpoints`). Each entry's cost is
    booked half on frame t and half on t + 1, so that the solver's per-frame step acceptance
    and damping see it (a frame's cost then depends on its neighbours' steps: the solver
    evaluates every trial, mixtures of frames included, as a whole)."""

    name = "self_clearance_midpoints"

    def __init__(self, clearance: SelfClearance, weight: float, span: np.ndarray) -> None:
        """``span`` (T,) int: the span of each frame (frames of two spans are not coupled)."""
        self.clearance = clearance
        self.weight = weight
        self.coupled = coupled_pairs(span)

    def evaluate(self, cfg: Configuration) -> MidpointClearanceValue:
        close = midpoint_pairs(cfg.poses, self.clearance, self.coupled)
        cost = np.zeros(len(cfg.q))
        half = 0.5 * self.weight * (close.dist - close.limit) ** 2
        np.add.at(cost, close.frame, half)
        np.add.at(cost, close.frame + 1, half)
        return MidpointClearanceValue(cost, close)

    def linearise(self, cfg: Configuration, value: MidpointClearanceValue, eq: NormalEquations) -> None:
        """The residual's row is (J_t, J_t+1) / 2 (:mod:`retarget.midpoints`; the limit, the
        margin or up to the chord's slack less, is held fixed). Its Gauss-Newton block
        w J^T J couples the two frames; it is bounded by twice its two diagonal blocks
        (as the banded solve's lag-2 couplings are), so each frame gets 2 w (J_f / 2)^T (J_f / 2)
        and the exact gradient w (J_f / 2)^T r."""
        close, sc = value.close, self.clearance
        if not close.frame.size:
            return
        u = _unit((close.pa + close.pa_next) - (close.pb + close.pb_next))
        tree, poses = cfg.robot.tree, cfg.poses
        na, nb = sc.node[sc.first[close.pair]], sc.node[sc.second[close.pair]]
        res = close.dist - close.limit
        ends = ((close.frame, close.pa, close.pb), (close.frame + 1, close.pa_next, close.pb_next))
        for frame, pa, pb in ends:
            ja = tree.directional_jacobian(poses, frame, na, pa, u)
            row = 0.5 * (ja - tree.directional_jacobian(poses, frame, nb, pb, u))
            eq.rows.append(SparseRows(frame, np.sqrt(2 * self.weight) * row, np.sqrt(self.weight / 2) * res))

    def violation(self, cfg: Configuration, value: MidpointClearanceValue) -> np.ndarray | None:
        """Overlap (m) of the deepest averaged pair next to each frame (0: none overlaps)."""
        if not value.close.frame.size:
            return None
        worst = np.zeros(len(cfg.q))
        np.maximum.at(worst, value.close.frame, -value.close.dist)
        np.maximum.at(worst, value.close.frame + 1, -value.close.dist)
        return worst
