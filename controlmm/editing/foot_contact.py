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


CONTACT_CONTROL_WEIGHTS = (10.0, 1.0)
"""Weights of the control loss (and its hinge) in the foot-contact run's tries, in order. The run
keeps only states that still meet every constraint, and codebook editing ends with them right at the
tolerance: how far a try gets before its line searches leave the constraints depends on rounding,
so on the CPU. Weighed 1, the test walk's sliding fell by half on a 2-core AMD EPYC and by 0.2 % on a
2-core Intel Xeon (seeds 0-3 there: 0.2-58 %); weighed 10, by 82-99.9 % on those four walks on the
Intel machine (2026-12-02, 16:00 UTC) but by 9 % (seed 0) and 17.5 % (seed 1) on another AMD EPYC
later that day, where weighed 1 it fell by 100 % (seed 0). A second try runs where the first stalled:
it left a sample sliding more than CONTACT_ENOUGH of what it did before the run."""
CONTACT_ENOUGH = 0.8
"""A try that leaves a sample's sliding (:func:`foot_contact_term`) at most this fraction of what it
was before the run ends the run for it (with 0.5 the plan benchmark's CPU time per plan rose by 19 %,
with 0.8 by 14 %, the passes alike: 2026-12-02, the AMD machine)."""


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
    that met its constraints only just still gains from the run). The control loss and its hinge
    weigh CONTACT_CONTROL_WEIGHTS[0]; where that try leaves a sample sliding more than CONTACT_ENOUGH
    of what it did before, the next weight tries again from ``latent``. Sample i takes the latent of
    the try that slides least, only where it meets ``objective`` and slides less than ``latent``
    (``kept[i]``), else keeps ``latent``. ``decode``: latent -> joints (B, T, 22, 3), differentiable.
    """
    kept = torch.zeros(latent.shape[0], dtype=torch.bool, device=latent.device)
    if config.contact_steps == 0:
        return latent, kept
    sliding = foot_contact_term(1.0)
    with torch.no_grad():
        joints = decode(latent)
        _, done_before, _ = objective.evaluate(joints)
        before = sliding(joints)
    best, least = latent, before

    def meets(joints: torch.Tensor) -> torch.Tensor:  # only states that still meet the objective count
        return objective.evaluate(joints)[1]

    contact = replace(
        objective,
        terms=tuple(objective.terms) + (foot_contact_term(config.contact_weight),),
        hinge_weight=config.contact_hinge_weight,
    )
    steps = replace(config, codebook_steps=config.contact_steps)
    for weight in CONTACT_CONTROL_WEIGHTS:
        todo = done_before & (least > CONTACT_ENOUGH * before)
        if not bool(todo.any()):  # no sample could keep a try's result, or none needs another
            break
        with torch.enable_grad():
            outcome = codebook_editing(
                latent, decode, replace(contact, control_weight=weight), steps, admissible=meets
            )
        with torch.no_grad():
            joints = decode(outcome.param)
            _, done_after, _ = objective.evaluate(joints)
            now = sliding(joints)
        better = todo & done_after & (now < least)
        best = torch.where(better[:, None, None], outcome.param.detach(), best)
        least = torch.where(better, now, least)
        kept = kept | better
    return best, kept
