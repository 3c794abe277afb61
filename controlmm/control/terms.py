"""Loss terms for inference-time editing (logits editing and codebook editing).

A loss term maps generated global joints to a per-sample loss:

    fn(joints: Tensor (B, T, 22, 3)) -> Tensor (B,)   (>= 0, 0 when satisfied)

``joints`` are in the human frame (Y up, metres, the motion's frames 0..T-1 at 20 fps) and are
differentiable; the editors minimise ``sum(term.weight * term.fn(joints))``. Spatial control
targets, obstacle SDF losses (``scenes``), floor losses and simulation-feedback losses are all
loss terms, so the editors need to know nothing about where a loss comes from.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch

from controlmm.errors import ControlMMError

JointLossFn = Callable[[torch.Tensor], torch.Tensor]


@dataclass(frozen=True)
class LossTerm:
    """A named, weighted loss on generated joints.

    Attributes:
        name: short label used in logs and reports (e.g. ``"control"``, ``"obstacle:table"``).
        fn: ``(B, T, 22, 3) -> (B,)`` differentiable per-sample loss.
        weight: multiplier applied by the editors.
    """

    name: str
    fn: JointLossFn
    weight: float = 1.0

    def __call__(self, joints: torch.Tensor) -> torch.Tensor:
        value = self.fn(joints)
        if value.shape != joints.shape[:1]:
            raise ControlMMError(
                f"loss term '{self.name}' returned shape {tuple(value.shape)}; expected ({joints.shape[0]},)"
            )
        return self.weight * value


def total_loss(terms: Sequence[LossTerm], joints: torch.Tensor) -> torch.Tensor:
    """Sum of weighted per-sample losses, (B,); zeros when there are no terms."""
    total = joints.new_zeros(joints.shape[0])
    for term in terms:
        total = total + term(joints)
    return total
