"""The control loss (ControlMM's L_ctrl) and per-constraint errors."""

from __future__ import annotations

import numpy as np
import torch

from controlmm.control.spec import ControlSpec
from controlmm.control.terms import LossTerm
from controlmm.frames import HumanToWorld


def control_loss(joints: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Squared error on controlled joints, normalised per sample (ControlMM's inference loss, L_ctrl).

    Args:
        joints: (B, T, 22, 3) generated joints, human frame.
        targets: (B, T, 22, 3) or (T, 22, 3) target positions (ignored where not masked).
        mask: (B, T, 22) or (T, 22) bool, True where controlled.

    Returns:
        (B,) sum over controlled (t, j, xyz) of squared error / max(1, 3 * #controlled).
    """
    t = joints.shape[1]
    targets = targets[..., :t, :, :].to(joints)
    mask = mask[..., :t, :].to(joints.device, torch.bool)
    weight = mask.to(joints.dtype).unsqueeze(-1)
    sq = ((joints - targets) * weight).square().sum(dim=(1, 2, 3))
    count = weight.expand(*weight.shape[:-1], 3).sum(dim=tuple(range(weight.ndim - 3, weight.ndim)))
    return sq / count.clamp(min=1.0)


def control_loss_term(targets: torch.Tensor, mask: torch.Tensor, weight: float = 1.0) -> LossTerm:
    """Wrap :func:`control_loss` for fixed targets as a :class:`LossTerm` for the editors."""
    return LossTerm("control", lambda joints: control_loss(joints, targets, mask), weight)


def constraint_errors(
    joints: np.ndarray, spec: ControlSpec, transform: HumanToWorld | None = None
) -> np.ndarray:
    """Euclidean error (m) of each constraint of ``spec`` on joints (T, 22, 3), (K,) in the human frame."""
    spec.check_length(len(joints))
    pos = spec.human_positions(transform)
    got = np.array([joints[c.frame, c.joint] for c in spec.constraints], dtype=np.float64).reshape(-1, 3)
    return np.linalg.norm(got - pos, axis=-1)
