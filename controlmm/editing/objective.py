"""What the editors minimise and when they stop.

An :class:`Objective` is the spatial-control targets (optional) plus any other :class:`LossTerm`s
(obstacle SDF, floor, simulation feedback...). Per sample:

    loss(joints)  = control_weight * (L_ctrl + hinge_weight * H)(joints) + sum_k w_k term_k(joints)   (B,)
    done(joints)  = every constraint within ``tolerance`` (m)  and  every other term <= ``loss_tolerance``

``L_ctrl`` is ControlMM's inference loss (squared error over the controlled (t, j, xyz) entries divided
by their number, per sample, as in the official code); H (:meth:`Objective.control_hinge`) pulls on the
constraints still over half the tolerance (codebook editing uses it, weight 10). Stopping looks at the
worst constraint, not the mean, so an early-stopped motion meets *every* constraint to the tolerance
(``stop_on="max"``); logits editing, which only steers the sampling of the tokens, stops on the mean
error (``stop_on="mean"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import torch

from controlmm.control.loss import control_loss
from controlmm.control.terms import LossTerm


@dataclass
class Objective:
    """Control targets (B, T, 22, 3) with mask (B, T, 22) and other loss terms on joints (B, T, 22, 3).

    ``targets``/``mask`` cover the frames the editors decode (frames past a motion's end are never
    controlled). ``terms`` are called on the same joints.
    """

    targets: torch.Tensor | None = None
    mask: torch.Tensor | None = None
    terms: Sequence[LossTerm] = field(default_factory=tuple)
    tolerance: float = 0.01
    loss_tolerance: float = 1e-6
    control_weight: float = 1.0
    stop_on: str = (
        "max"  # "max": every constraint within tolerance; "mean": their mean error (logits editing)
    )
    hinge_weight: float = (
        0.0  # extra weight on the constraints still over half the tolerance (see control_hinge)
    )

    def __post_init__(self) -> None:
        if (self.targets is None) != (self.mask is None):
            raise ValueError("targets and mask go together")
        if self.stop_on not in ("max", "mean"):
            raise ValueError(f"stop_on must be 'max' or 'mean'; got {self.stop_on!r}")
        if self.mask is not None:
            self.mask = self.mask.bool()
        self.terms = tuple(self.terms)

    @property
    def has_control(self) -> bool:
        return self.mask is not None and bool(self.mask.any())

    @property
    def active(self) -> bool:
        """Whether there is anything to optimise at all."""
        return self.has_control or bool(self.terms)

    def _control(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(targets (B, T, 22, 3), mask (B, T, 22)); an error if the objective has none."""
        if self.targets is None or self.mask is None:
            raise ValueError("this objective has no control targets")
        return self.targets, self.mask

    def max_error(self, joints: torch.Tensor) -> torch.Tensor:
        """Worst constraint error per sample (B,) in metres (0 without constraints)."""
        if self.mask is None:
            return joints.new_zeros(joints.shape[0])
        targets, mask = self._control()
        t = joints.shape[1]
        err = (joints.detach() - targets[:, :t]).norm(dim=-1)
        return torch.where(mask[:, :t], err, torch.zeros_like(err)).flatten(1).amax(-1)

    def mean_error(self, joints: torch.Tensor) -> torch.Tensor:
        """Mean constraint error per sample (B,) in metres (0 without constraints)."""
        if self.mask is None:
            return joints.new_zeros(joints.shape[0])
        targets, mask = self._control()
        t = joints.shape[1]
        err = (joints.detach() - targets[:, :t]).norm(dim=-1)
        mask = mask[:, :t]
        total = torch.where(mask, err, torch.zeros_like(err)).flatten(1).sum(-1)
        return total / mask.flatten(1).sum(-1).clamp(min=1)

    def control_hinge(self, joints: torch.Tensor) -> torch.Tensor:
        """(B,) mean over the controlled entries of max(0, error - tolerance / 2)^2.

        Zero once every constraint is within half the tolerance; it pulls on the few constraints that
        lag behind, which the mean squared error barely feels once most constraints are met.
        """
        targets, mask = self._control()
        t = joints.shape[1]
        mask = mask[:, :t]
        err = ((joints - targets[:, :t].to(joints)).square().sum(-1) + 1e-12).sqrt()
        excess = torch.relu(err - 0.5 * self.tolerance).square()
        total = torch.where(mask, excess, torch.zeros_like(excess)).flatten(1).sum(-1)
        return total / mask.flatten(1).sum(-1).clamp(min=1)

    def term_values(self, joints: torch.Tensor) -> dict[str, torch.Tensor]:
        """Weighted per-sample value (B,) of every term, the control loss first (as ``control``)."""
        values: dict[str, torch.Tensor] = {}
        if self.has_control:
            targets, mask = self._control()
            value = control_loss(joints, targets, mask)
            if self.hinge_weight > 0:
                value = value + self.hinge_weight * self.control_hinge(joints)
            values["control"] = self.control_weight * value
        for term in self.terms:
            name = term.name if term.name not in values else f"{term.name}#{len(values)}"
            values[name] = term(joints)
        return values

    def evaluate(self, joints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(loss (B,) differentiable, done (B,) bool, worst constraint error (B,) m) of joints."""
        values = self.term_values(joints)
        loss = sum(values.values(), joints.new_zeros(joints.shape[0]))
        max_err = self.max_error(joints)
        done = (max_err if self.stop_on == "max" else self.mean_error(joints)) <= self.tolerance
        for name, value in values.items():
            if name != "control":
                done = done & (value.detach() <= self.loss_tolerance)
        return loss, done, max_err
