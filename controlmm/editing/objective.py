"""What the editors minimise and when they stop.

An :class:`Objective` is the spatial-control targets (optional) plus any other :class:`LossTerm`s
(obstacle SDF, floor, simulation feedback...). Per sample:

    loss(joints)  = control_weight * (L_ctrl + hinge_weight * H)(joints) + sum_k w_k term_k(joints)   (B,)
    done(joints)  = every constraint within ``tolerance`` (m)  and  every other term <= ``loss_tolerance``

``L_ctrl`` is ControlMM's inference loss (squared error over the controlled (t, j, xyz) entries divided
by their number, per sample, as in the official code); H (:meth:`Objective.control_hinge`) pulls on the
constraints still over half the tolerance (codebook editing uses it, weight 10). With
``difference_weight`` > 0 the control term also holds D (:meth:`Objective.keyframe_differences`): the
squared error of the *differences* between a joint's controlled keyframes k and k + s (s = 1, 2, 4, 8,
16 in keyframe order). D is zero wherever L_ctrl is, so the editors' solutions do not change, but it
conditions trajectory-like control: the pelvis integrates the decoded velocities over the clip, and
an error that L_ctrl sees only as a slow drift, D sees at the frames that cause it (a dense pelvis
trajectory meets 1 cm in about half the L-BFGS evaluations). Stopping looks at the
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
    difference_weight: float = 0.0  # weight of the keyframe-difference term (see keyframe_differences)
    difference_strides: tuple[int, ...] = (1, 2, 4, 8, 16)
    _pairs: dict[int, list[tuple[torch.Tensor, ...]]] = field(
        default_factory=dict, init=False, repr=False, compare=False
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

    def _keyframe_pairs(self, frames: int) -> list[tuple[torch.Tensor, ...]]:
        """Per stride s: (sample, frame k, frame k + s, joint, pairs per sample) index tensors of the
        controlled keyframes of each (sample, joint) among the first ``frames`` frames."""
        if frames not in self._pairs:
            _, mask = self._control()
            m = mask[:, :frames].transpose(1, 2)  # (B, 22, T)
            count = m.sum(-1)  # (B, 22)
            longest = int(count.max()) if m.numel() else 0
            rank = torch.where(m, m.long().cumsum(-1) - 1, longest)  # keyframe order; pads -> longest
            table = torch.full((*m.shape[:2], longest + 1), -1, dtype=torch.long, device=m.device)
            time = torch.arange(m.shape[-1], device=m.device).expand_as(rank)
            table.scatter_(2, rank, time)  # table[b, j, r] = frame of keyframe r (-1 past the last)
            table = table[..., :longest]
            pairs: list[tuple[torch.Tensor, ...]] = []
            for s in self.difference_strides:
                if s >= longest:
                    break
                first, second = table[..., :-s], table[..., s:]
                b, j, r = (second >= 0).nonzero(as_tuple=True)
                per_sample = torch.bincount(b, minlength=m.shape[0]).clamp(min=1)
                pairs.append((b, first[b, j, r], second[b, j, r], j, per_sample))
            self._pairs[frames] = pairs
        return self._pairs[frames]

    def keyframe_differences(self, joints: torch.Tensor) -> torch.Tensor:
        """(B,) sum over strides s of the mean over keyframe pairs (k, k + s) of each controlled joint
        of ||(x_{k+s} - x_k) - (y_{k+s} - y_k)||^2 / 3 (x the joints, y the targets; per coordinate like
        L_ctrl). Zero without pairs."""
        targets, _ = self._control()
        y = targets.to(joints)
        total = joints.new_zeros(joints.shape[0])
        for b, first, second, j, per_sample in self._keyframe_pairs(joints.shape[1]):
            d = (joints[b, second, j] - joints[b, first, j]) - (y[b, second, j] - y[b, first, j])
            total = total + torch.zeros_like(total).index_add(0, b, d.square().sum(-1)) / (3 * per_sample)
        return total

    def term_values(self, joints: torch.Tensor) -> dict[str, torch.Tensor]:
        """Weighted per-sample value (B,) of every term, the control loss first (as ``control``)."""
        values: dict[str, torch.Tensor] = {}
        if self.has_control:
            targets, mask = self._control()
            value = control_loss(joints, targets, mask)
            if self.hinge_weight > 0:
                value = value + self.hinge_weight * self.control_hinge(joints)
            if self.difference_weight > 0:
                value = value + self.difference_weight * self.keyframe_differences(joints)
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
