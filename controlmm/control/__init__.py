"""Spatial control: the control specification, control loss and per-constraint errors."""

from controlmm.control.loss import constraint_errors, control_loss, control_loss_term
from controlmm.control.spec import Constraint, ControlSpec

__all__ = ["Constraint", "ControlSpec", "constraint_errors", "control_loss", "control_loss_term"]
