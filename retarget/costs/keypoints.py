"""Keypoint positions: ``sum_k w_k(t) |p_k(t) - target_k(t)|^2`` (metres).

Every mapped keypoint (a point fixed on a robot body) follows its refined human target
(:func:`retarget.targets.build_targets`); ``w_k(t)`` is the mapping's position weight, raised
in stance for the foot keypoints (the foot locks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.targets import Targets


@dataclass
class KeypointValue(TermValue):
    """``res``: (T, K, 3) keypoint position minus target (m)."""

    res: np.ndarray


class KeypointCost(CostTerm[KeypointValue]):
    """Weighted squared distances of the keypoints to their targets."""

    name = "keypoints"

    def __init__(self, targets: Targets) -> None:
        self.target = targets.kp_pos  # (T, K, 3)
        self.weight = targets.kp_weight  # (T, K)
        self.matrix = self.weight[:, :, None] * np.eye(self.weight.shape[1])  # (T, K, K) diag(w_k(t))

    def evaluate(self, cfg: Configuration) -> KeypointValue:
        res = cfg.keypoints - self.target
        return KeypointValue(np.sum(self.weight * np.sum(res**2, axis=-1), axis=1), res)

    def linearise(self, cfg: Configuration, value: KeypointValue, eq: NormalEquations) -> None:
        eq.add_keypoints(self.matrix, self.weight[..., None] * value.res)
