"""The foot-contact run: a second codebook-editing run that takes the skating out of an edited motion.

Editing moves a motion onto its targets by changing the decoder latent, and the feet that were planted
start to slide (docs/benchmarks-history.md, "Control", "The fourth update's default": foot skating 0.05 ->
0.12 with the accurate preset on that default model). Putting a contact term into the editors' objective
from the start fights the targets; instead, once codebook editing has met them, this run edits the
latent again with the same objective plus :func:`foot_contact_term`, and a sample keeps the result only
where it still meets the whole objective (every constraint within the tolerance, every other term met).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import torch

from controlmm.control.terms import LossTerm
from controlmm.editing.codebook_editing import codebook_editing
from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig
from controlmm.motion.geometry import FOOT_JOINTS, SKATE_HEIGHT, SKATE_SPEED
from controlmm.motion.skeleton import FPS

# Contact and sliding follow the foot-skating ratio's rule (controlmm.motion.geometry.foot_skating_ratio):
# a foot (joints 10, 11) below SKATE_HEIGHT (m) at t and t+1 is in contact; above SKATE_SPEED (m/s) it slides.


CONTACT_CONTROL_WEIGHT = 10.0
"""Weight of the control loss (and its hinge) in the foot-contact run. The run keeps only states
that still meet every constraint, and codebook editing ends with them right at the tolerance:
weighed 1, the sliding term's gradient led every line search out of the constraints, and how far
the run got depended on rounding (the test walk's sliding fell by half on a 2-core AMD EPYC, by
0.2 % on a 2-core Intel Xeon; seeds 0-3 there: 0.2-58 %). Weighed 10 it fell by 82-99.9 % on
those four walks, every constraint within 0.7 cm (2026-12-02, the Intel machine)."""


def foot_contact_term(
    weight: float, height: float = SKATE_HEIGHT, speed: float = SKATE_SPEED, fps: float = FPS
) -> LossTerm:
    """Feet in contact do not slide: sum over frames and feet of relu(planar speed - ``speed``)^2 / T.

    Contact (a foot below ``height`` metres at t and t+1, human frame, Y up) is read from the joints
    being edited but not differentiated, so the term cannot be met by lifting a foot. Units: (m/s)^2.
    """
    feet = list(FOOT_JOINTS)

    def fn(joints: torch.Tensor) -> torch.Tensor:
        f = joints[:, :, feet]
        v = (f[:, 1:, :, [0, 2]] - f[:, :-1, :, [0, 2]]).norm(dim=-1) * fps  # (B, T-1, 2) m/s
        low = (f[:, :, :, 1] < height).detach()
        contact = (low[:, 1:] & low[:, :-1]).to(joints.dtype)
        return (contact * torch.relu(v - speed).square()).sum(dim=(1, 2)) / joints.shape[1]

    return LossTerm("foot_contact", fn, weight)


def foot_contact_run(
    latent: torch.Tensor,
    decode: Callable[[torch.Tensor], torch.Tensor],
    objective: Objective,
    config: EditingConfig,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Re-edit a latent (B, N, code_dim) that codebook editing produced; returns (latent, kept (B,) bool).

    Runs ``config.contact_steps`` codebook-editing steps on ``objective`` plus
    ``foot_contact_term(config.contact_weight)`` from ``latent``, with the hinge on the constraints
    over half the tolerance weighted ``config.contact_hinge_weight`` (codebook editing stops as soon as
    every constraint is within the tolerance, often right at it; how hard to pull back depends on the
    model, docs/control.md), keeping the best state that still
    meets ``objective`` (a step that trades a constraint for less sliding is never kept, so a motion
    that met its constraints only just still gains from the run); sample i takes the new latent only
    where it meets ``objective`` (``kept[i]``), else keeps ``latent``. ``decode``: latent ->
    joints (B, T, 22, 3), differentiable.
    """
    kept = torch.zeros(latent.shape[0], dtype=torch.bool, device=latent.device)
    if config.contact_steps == 0:
        return latent, kept
    with torch.no_grad():
        _, done_before, _ = objective.evaluate(decode(latent))
    if not bool(done_before.any()):  # no sample could keep the run's result
        return latent, kept
    contact = replace(
        objective,
        terms=tuple(objective.terms) + (foot_contact_term(config.contact_weight),),
        hinge_weight=config.contact_hinge_weight,
        control_weight=CONTACT_CONTROL_WEIGHT,
    )

    def meets(joints: torch.Tensor) -> torch.Tensor:  # only states that still meet the objective count
        return objective.evaluate(joints)[1]

    with torch.enable_grad():
        outcome = codebook_editing(
            latent, decode, contact, replace(config, codebook_steps=config.contact_steps), admissible=meets
        )
    with torch.no_grad():
        _, done_after, _ = objective.evaluate(decode(outcome.param))
    kept = done_before & done_after
    return torch.where(kept[:, None, None], outcome.param.detach(), latent), kept
