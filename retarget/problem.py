"""One retargeting problem: its cost terms evaluated and linearised over all frames.

A :class:`Problem` holds the terms of :func:`retarget.costs.default_costs` for a set of
targets, evaluates them at a configuration of all frames (a :class:`State`: the cost of
every frame and of every span) and assembles the Gauss-Newton normal equations that the
solver (:mod:`retarget.solver`) solves with :class:`retarget.banded.BandedSystem`.
Spans: frames may form independent spans side by side (no velocity/acceleration term
couples frames of different spans), each accepting or refusing its steps on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.banded import BandedSystem
from retarget.costs import Configuration, CostTerm, NormalEquations, TermValue, default_costs
from retarget.reference import reference_root
from retarget.robot_model import RobotModel
from retarget.solver_config import SolverConfig
from retarget.targets import Targets


@dataclass
class State:
    """One configuration of all frames with its term values and costs.

    Attributes:
        cfg: the configuration; values: one :class:`TermValue` per term of the problem.
        cost: total cost; frame_cost: (T,) cost of the per-frame terms in each frame;
        span_cost: (S,) total cost (temporal terms included) of each span.
    """

    cfg: Configuration
    values: list[TermValue]
    cost: float
    frame_cost: np.ndarray
    span_cost: np.ndarray

    @property
    def root_pos(self) -> np.ndarray:
        return self.cfg.root_pos

    @property
    def root_rot(self) -> np.ndarray:
        return self.cfg.root_rot

    @property
    def q(self) -> np.ndarray:
        return self.cfg.q

    def select(self, use: np.ndarray, other: State, spans: np.ndarray) -> State:
        """Frames ``use`` (T,) from this state, the others from ``other``, where ``use`` takes
        whole independent spans (``spans``: (S,) bool, the spans taken): no re-evaluation,
        since no term couples frames of different spans."""
        span_cost = np.where(spans, self.span_cost, other.span_cost)
        return State(
            self.cfg.select(use, other.cfg),
            [mine.select(use, theirs) for mine, theirs in zip(self.values, other.values, strict=True)],
            float(span_cost.sum()),
            np.where(use, self.frame_cost, other.frame_cost),
            span_cost,
        )


class Problem:
    """Cost terms, their evaluation and the banded normal equations of one retargeting problem."""

    def __init__(
        self,
        robot: RobotModel,
        targets: Targets,
        config: SolverConfig,
        ref_pos: np.ndarray | None = None,
        span: np.ndarray | None = None,
    ) -> None:
        """``ref_pos`` (T, 3): the root's temporal reference (default: the smoothed pelvis of
        ``targets``, :func:`retarget.reference.reference_root`); ``span`` (T,) int: independent
        spans of frames side by side (default: one span)."""
        self.robot, self.targets, self.config = robot, targets, config
        self.t_len = targets.kp_pos.shape[0]
        self.n = robot.tree.nv
        self.span = np.zeros(self.t_len, dtype=int) if span is None else np.asarray(span, dtype=int)
        self.n_spans = int(self.span.max()) + 1 if self.t_len else 1
        self.span_frames = np.bincount(self.span, minlength=self.n_spans)  # (S,) frames per span
        if ref_pos is None:
            ref_pos = reference_root(robot, targets)
        self.ref_x = np.zeros((len(ref_pos), self.n))
        self.ref_x[:, :3] = ref_pos
        self.terms: list[CostTerm] = default_costs(robot, targets, config, self.ref_x, self.span)
        self.band = BandedSystem(self.t_len, self.n, self.terms)

    def evaluate(self, root_pos: np.ndarray, root_rot: np.ndarray, q: np.ndarray) -> State:
        """Forward kinematics, every term's residuals and the costs at root_pos (T, 3),
        root_rot (T, 3, 3), q (T, nj)."""
        cfg = Configuration.at(self.robot, root_pos, root_rot, q)
        values = [term.evaluate(cfg) for term in self.terms]
        frame_cost = np.zeros(self.t_len)
        for term, value in zip(self.terms, values, strict=True):
            if not term.couples_frames:
                frame_cost = frame_cost + value.cost
        span_cost = np.bincount(self.span, frame_cost, self.n_spans)
        for term, value in zip(self.terms, values, strict=True):
            if term.couples_frames:
                span_cost = span_cost + np.bincount(self.span, value.cost, self.n_spans)
        return State(cfg, values, float(span_cost.sum()), frame_cost, span_cost)

    def span_max(self, values: np.ndarray, floor: float = -np.inf) -> np.ndarray:
        """(S,) the largest of per-frame ``values`` (T,) in each span (``floor`` if none is larger)."""
        out = np.full(self.n_spans, floor)
        np.maximum.at(out, self.span, values)
        return out

    def frame_violation(self, st: State) -> np.ndarray:
        """(T,) how deep (m) each frame violates the hard constraints: capsules overlapping
        each other, a body's support points below the floor, a swing foot below half its
        clearance (the terms' margins are only their soft zone: the check sees an overlap
        of the real geometry, which the capsules enclose)."""
        worst = np.zeros(self.t_len)
        for term, value in zip(self.terms, st.values, strict=True):
            v = term.violation(st.cfg, value)
            if v is not None:
                worst = np.maximum(worst, v)
        return worst

    def normal_equations(self, st: State) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton blocks H (T, n, n) of the per-frame terms and the gradient g (T, n)
        of all terms (half the cost's gradient) at ``st``; the constant couplings of the
        temporal terms are in :attr:`band`."""
        eq = NormalEquations(self.t_len, self.n)
        for term, value in zip(self.terms, st.values, strict=True):
            term.linearise(st.cfg, value, eq)
        return eq.finish(st.cfg)

    def term_costs(self, st: State) -> dict[str, float]:
        """Total cost of each term at ``st`` (by term name)."""
        return {term.name: float(value.cost.sum()) for term, value in zip(self.terms, st.values, strict=True)}
