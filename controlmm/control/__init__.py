"""Spatial control: the control specification, loss terms on generated joints and the control loss.

- :class:`ControlSpec` / :class:`Constraint`: which joint should be where, at which frame;
- :class:`LossTerm` / :func:`total_loss`: the one loss interface of the editors (control, obstacles,
  feedback...);
- :func:`control_loss`, :func:`control_loss_term`, :func:`constraint_errors`: ControlMM's L_ctrl and
  per-constraint errors.

Generation under control is :func:`controlmm.generate.generate_controlled`; the evaluation protocol is
:mod:`controlmm.eval.control`.
"""

from controlmm.control.loss import constraint_errors, control_loss, control_loss_term
from controlmm.control.reach import reach_warnings
from controlmm.control.spec import Constraint, ControlSpec
from controlmm.control.terms import LossTerm, total_loss

__all__ = [
    "Constraint",
    "ControlSpec",
    "LossTerm",
    "constraint_errors",
    "control_loss",
    "control_loss_term",
    "reach_warnings",
    "total_loss",
]
