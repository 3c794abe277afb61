"""Joint couplings: ``sum_e w (q_a - p_e(q_b))^2`` over the MJCF's joint equalities.

Each driven joint ``a`` follows its driving joint ``b`` through the equality's polynomial
(:class:`retarget.couplings.JointCouplings`), weighted ``w`` (SolverConfig.w_coupling, per
rad^2) so stiffly that the output's exact projection moves a joint by a hair.
"""

from __future__ import annotations

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.couplings import JointCouplings


class CouplingCost(CostTerm[TermValue]):
    """Weighted squared residuals of the joint couplings (two joints per row, every frame)."""

    name = "coupling"

    def __init__(self, couplings: JointCouplings, weight: float) -> None:
        self.couplings = couplings
        self.weight = weight

    def evaluate(self, cfg: Configuration) -> TermValue:
        r = self.couplings.residual(cfg.q)  # (T, E)
        return TermValue(self.weight * np.sum(r**2, axis=1))

    def linearise(self, cfg: Configuration, value: TermValue, eq: NormalEquations) -> None:
        c = self.couplings
        r = c.residual(cfg.q)  # (T, E); its Jacobian: +1 at the driven joint, -slope at the driver
        slope = c.slope(cfg.q)
        w = self.weight
        for e in range(len(c.first)):
            a, b = 6 + int(c.first[e]), 6 + int(c.second[e])
            eq.h[:, a, a] += w
            eq.g[:, a] += w * r[:, e]
            if c.second[e] >= 0:
                eq.h[:, a, b] -= w * slope[:, e]
                eq.h[:, b, a] -= w * slope[:, e]
                eq.h[:, b, b] += w * slope[:, e] ** 2
                eq.g[:, b] -= w * slope[:, e] * r[:, e]
