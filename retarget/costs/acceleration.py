"""Acceleration: ``sum_c W_acc_c |x_c(t + 2) - 2 x_c(t + 1) + x_c(t)|^2`` over the temporal
values x (see :mod:`retarget.costs.temporal`). A linear residual: its Hessian is a constant
band of lag 2, or, by default, of lag 1 with the lag-2 couplings moved onto the diagonal."""

from __future__ import annotations

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.costs.temporal import REFERENCE_FPS, coordinate_weights, coupled_pairs, temporal_values


class AccelerationCost(CostTerm[TermValue]):
    """Weighted squared second differences of the root and joint sequences (per span)."""

    name = "acceleration"
    couples_frames = True

    def __init__(
        self, ref_x: np.ndarray, span: np.ndarray, fps: float, root: float, joint: float, exact: bool
    ) -> None:
        """``ref_x``, ``span``, ``fps`` as for :class:`~retarget.costs.velocity.VelocityCost`;
        ``root``, ``joint``: weights at 20 fps (rescaled by (fps / 20)^4); ``exact``: keep the
        lag-2 couplings in the banded matrix (twice the bandwidth)."""
        self.ref_x = ref_x
        self.exact = exact
        self.lag = 2 if exact else 1
        w = coordinate_weights(ref_x.shape[1], root, joint) * (fps / REFERENCE_FPS) ** 4
        coupled = coupled_pairs(span)
        self.weight = (coupled[:-1] & coupled[1:])[:, None] * w  # (T - 2, n)

    def evaluate(self, cfg: Configuration) -> TermValue:
        d2 = np.diff(temporal_values(cfg, self.ref_x), n=2, axis=0)
        cost = np.zeros(len(cfg.q))
        cost[: len(d2)] = np.sum(self.weight * d2 * d2, axis=1)
        return TermValue(cost)

    def linearise(self, cfg: Configuration, value: TermValue, eq: NormalEquations) -> None:
        if len(eq.g) > 2:
            x = temporal_values(cfg, self.ref_x)
            eq.g += np.diff(np.pad(np.diff(x, n=2, axis=0) * self.weight, ((2, 2), (0, 0))), n=2, axis=0)

    def add_band(self, d0: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> None:
        if len(d0) <= 2:
            return
        w = self.weight
        d0[:-2] += w
        d0[1:-1] += 4 * w
        d0[2:] += w
        d1[:-1] -= 2 * w
        d1[1:] -= 2 * w
        d2 += w
        if not self.exact:
            # Drop the lag-2 couplings from the matrix (bandwidth n instead of 2n) and add
            # their absolute value to the diagonal: the matrix stays an upper bound of the
            # true Hessian, the gradient stays exact, so LM still converges to the same optimum.
            d0[:-2] += w
            d0[2:] += w
