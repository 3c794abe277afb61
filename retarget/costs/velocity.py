"""Velocity: ``sum_c W_vel_c |x_c(t + 1) - x_c(t)|^2`` over the temporal values x (see
:mod:`retarget.costs.temporal`). A linear residual: its Hessian is a constant band."""

from __future__ import annotations

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.costs.temporal import REFERENCE_FPS, coordinate_weights, coupled_pairs, temporal_values


class VelocityCost(CostTerm[TermValue]):
    """Weighted squared first differences of the root and joint sequences (per span)."""

    name = "velocity"
    couples_frames = True
    lag = 1

    def __init__(
        self,
        ref_x: np.ndarray,
        span: np.ndarray,
        fps: float,
        root: float,
        joint: float | np.ndarray,
        gain: np.ndarray | None = None,
    ) -> None:
        """``ref_x`` (T, n): reference of x; ``span`` (T,) int: span of each frame; ``fps``:
        frame rate; ``root``, ``joint`` (a number or one per joint): weights at 20 fps
        (rescaled by (fps / 20)^2); ``gain`` (T, nj): a factor on each joint's weight, the
        larger of a pair's two frames' (``Targets.speed_gain``)."""
        self.ref_x = ref_x
        w = coordinate_weights(ref_x.shape[1], root, joint) * (fps / REFERENCE_FPS) ** 2
        self.weight = coupled_pairs(span)[:, None] * w  # (T - 1, n)
        if gain is not None and len(gain) > 1:
            self.weight[:, 6:] *= np.maximum(gain[:-1], gain[1:])

    def evaluate(self, cfg: Configuration) -> TermValue:
        d1 = np.diff(temporal_values(cfg, self.ref_x), axis=0)
        cost = np.zeros(len(cfg.q))
        cost[:-1] = np.sum(self.weight * d1 * d1, axis=1)
        return TermValue(cost)

    def linearise(self, cfg: Configuration, value: TermValue, eq: NormalEquations) -> None:
        if len(eq.g) > 1:
            x = temporal_values(cfg, self.ref_x)
            eq.g -= np.diff(np.pad(np.diff(x, axis=0) * self.weight, ((1, 1), (0, 0))), axis=0)

    def add_band(self, d0: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> None:
        if len(d0) > 1:
            d0[:-1] += self.weight
            d0[1:] += self.weight
            d1 -= self.weight
