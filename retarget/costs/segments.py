"""Segment vectors: ``sum_s w_s |(p_child - p_parent)(t) - seg_s(t)|^2`` (metres).

A segment joins a keypoint to its nearest mapped human ancestor; its target is the refined
human bone (the robot's length along the human's direction), so the limbs keep the human's
directions even where absolute positions cannot all be met.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.costs.base import Configuration, CostTerm, NormalEquations, TermValue
from retarget.targets import Targets


@dataclass
class SegmentValue(TermValue):
    """``res``: (T, S, 3) segment vector minus target (m)."""

    res: np.ndarray


class SegmentCost(CostTerm[SegmentValue]):
    """Weighted squared errors of the child - parent keypoint vectors.

    With the incidence matrix E (K, S) (+1 at the child, -1 at the parent), the Gauss-Newton
    block is ``J^T ((E diag(w) E^T) (x) I3) J`` with J the keypoints' Jacobian.
    """

    name = "segments"

    def __init__(self, targets: Targets) -> None:
        self.parent, self.child = targets.seg_parent, targets.seg_child  # (S,)
        self.target = targets.seg_vec  # (T, S, 3)
        self.weight = targets.seg_weight  # (S,)
        inc = np.zeros((targets.kp_pos.shape[1], len(self.child)))
        inc[self.child, np.arange(inc.shape[1])] = 1.0
        inc[self.parent, np.arange(inc.shape[1])] = -1.0
        self.incidence = inc
        self.matrix = (inc * self.weight) @ inc.T  # (K, K)

    def evaluate(self, cfg: Configuration) -> SegmentValue:
        kp = cfg.keypoints
        res = kp[:, self.child] - kp[:, self.parent] - self.target
        return SegmentValue(np.sum(self.weight * np.sum(res**2, axis=-1), axis=1), res)

    def linearise(self, cfg: Configuration, value: SegmentValue, eq: NormalEquations) -> None:
        eq.add_keypoints(self.matrix, self.incidence @ (self.weight[:, None] * value.res))
