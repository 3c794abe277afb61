"""Spatial control: the control specification, control loss, per-constraint errors and the evaluation
protocol (:mod:`controlmm.control.evaluation`).

Generation under control is :func:`controlmm.generate.generate_controlled`.
"""

from controlmm.control.loss import constraint_errors, control_loss, control_loss_term
from controlmm.control.spec import Constraint, ControlSpec

__all__ = ["Constraint", "ControlSpec", "constraint_errors", "control_loss", "control_loss_term"]
