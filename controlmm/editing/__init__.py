"""Inference-time editing: the objective on generated joints, logits editing, codebook editing.

- :class:`Objective`: control targets + loss terms (:class:`controlmm.control.LossTerm`) + the
  early-stopping rule;
- :func:`logits_editing`, :func:`codebook_editing`: the two editors (ControlMM paper §3.3; docs/control.md);
- :class:`EditingConfig`, :data:`PRESETS` (``fast``, ``medium``, ``accurate``), :func:`editing_preset`.

Controlled generation itself (decoding with the control model and both editors) is
:func:`controlmm.generate.generate_controlled`.
"""

from controlmm.editing.codebook_editing import codebook_editing
from controlmm.editing.logits_editing import logits_editing
from controlmm.editing.objective import Objective
from controlmm.editing.optimize import EditOutcome, optimize
from controlmm.editing.presets import PRESETS, EditingConfig, editing_preset

__all__ = [
    "PRESETS",
    "EditOutcome",
    "EditingConfig",
    "Objective",
    "codebook_editing",
    "editing_preset",
    "logits_editing",
    "optimize",
]
