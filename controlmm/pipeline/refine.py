"""Codebook editing of one motion across plan rounds.

The plan generates the tokens once (masked decoding with the motion control model and logits
editing), then owns the codebook-editing stage: the decoder latent of round k starts from round
k-1's edited latent and is optimised against the control targets, the scene's losses and every
feedback term so far. A feedback round therefore changes the motion only as much as its losses ask,
keeps what earlier rounds fixed, and costs a codebook-editing run instead of a whole generation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from controlmm.control.spec import ControlSpec
from controlmm.control.terms import LossTerm
from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig
from controlmm.frames import HumanToWorld
from controlmm.generate.controlled import decode_latent, edit_latent
from controlmm.motion.container import Motion
from controlmm.motion.skeleton import FPS, NUM_JOINTS


@dataclass
class EditedMotion:
    """The result of one codebook-editing run."""

    latent: torch.Tensor  # (1, N, code_dim) edited decoder latent
    motion: Motion
    errors: list[float]  # metres, one per constraint of the spec (spec order)
    record: dict[str, Any]
    seconds: dict[str, float] = field(default_factory=dict)  # codebook_editing, foot_contact, decoding


def control_targets(
    spec: ControlSpec | None, frames: int, transform: HumanToWorld
) -> tuple[torch.Tensor, torch.Tensor]:
    """Dense targets (1, T, 22, 3) and mask (1, T, 22) in the human frame (zeros/False without a spec)."""
    if spec is None:
        return torch.zeros(1, frames, NUM_JOINTS, 3), torch.zeros(1, frames, NUM_JOINTS, dtype=torch.bool)
    targets, mask = spec.dense(frames, transform)
    return torch.as_tensor(targets, dtype=torch.float32)[None], torch.as_tensor(mask)[None]


def edit_motion(
    model,
    latent: torch.Tensor,
    frames: int,
    spec: ControlSpec | None,
    transform: HumanToWorld,
    terms: list[LossTerm],
    config: EditingConfig,
    text: str,
    metadata: dict | None = None,
) -> EditedMotion:
    """Codebook-edit ``latent`` (1, N, code_dim) so the motion's first ``frames`` frames meet the
    spec and the loss terms; returns the edited latent and the decoded :class:`Motion`."""
    targets, mask = control_targets(spec, frames, transform)
    objective = Objective(
        targets=targets,
        mask=mask,
        terms=terms,
        tolerance=config.tolerance,
        loss_tolerance=config.loss_tolerance,
    )
    latent, edit = edit_latent(model, latent, frames, objective, config)
    started = time.perf_counter()
    joints, features = decode_latent(model, latent, frames)
    errors: list[float] = []
    extras: dict[str, np.ndarray] = {}
    if spec is not None:
        t_np, m_np = targets[0].numpy(), mask[0].numpy()
        errors = [
            float(np.linalg.norm(joints[c.frame, c.joint] - t_np[c.frame, c.joint])) for c in spec.constraints
        ]
        extras = {
            "control_mask": m_np,
            "control_targets": t_np,
            "control_errors": np.asarray(errors, np.float32),
        }
    record = {
        "codebook_steps": edit["steps"],
        "codebook_budget": config.codebook_steps,
        "converged": edit["converged"],
        "max_error_m": max(errors, default=0.0),
        "losses": edit["losses"],
    }
    motion = Motion(
        joints=joints.astype(np.float32),
        fps=float(FPS),
        features=features.astype(np.float32),
        text=text,
        metadata=dict(metadata or {}),
        extras=extras,
    )
    seconds = {**edit.get("seconds", {}), "decoding": time.perf_counter() - started}
    return EditedMotion(latent=latent, motion=motion, errors=errors, record=record, seconds=seconds)
