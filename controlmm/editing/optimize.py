"""The optimisation loop shared by logits editing and codebook editing.

A per-sample tensor ``param`` (B, ...) is optimised with a fresh AdamW against an
:class:`~controlmm.editing.objective.Objective` on the joints ``forward(param)`` decodes. Samples stop
one by one: once a sample is done (every constraint within tolerance, other terms ~0) its row is
frozen at that state (restored after every later optimiser step) and it no longer counts in the
loss. The loop ends when every sample is done or the step budget is spent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from controlmm.editing.objective import Objective
from controlmm.editing.presets import EditingConfig


@dataclass
class EditOutcome:
    """Per-sample result of one editing run."""

    param: torch.Tensor  # (B, ...) the edited tensor (detached)
    steps: torch.Tensor  # (B,) long, optimiser steps each sample took
    done: torch.Tensor  # (B,) bool, met the stopping criterion
    loss: torch.Tensor  # (B,) objective of the returned state (as last evaluated)
    max_error: torch.Tensor  # (B,) worst constraint error (m) of the returned state


def optimize(param: torch.Tensor, forward: Callable[[torch.Tensor], torch.Tensor], objective: Objective,
             steps: int, config: EditingConfig, keep_best: bool = True) -> EditOutcome:
    """Minimise ``objective(forward(param))`` over ``param`` for at most ``steps`` AdamW steps.

    Args:
        param: (B, ...) initial value (not modified).
        forward: param -> joints (B, T, 22, 3), differentiable.
        objective: the loss and the stopping rule.
        steps: step budget (0: only evaluate).
        config: optimiser settings and whether to stop early.
        keep_best: return, for samples that never finish, the evaluated state with the lowest loss
            (codebook editing); otherwise the last state (logits editing, whose loss is noisy).
    """
    b = param.shape[0]
    x = param.detach().clone().requires_grad_(True)
    optimizer = torch.optim.AdamW([x], lr=config.lr, betas=config.betas, weight_decay=config.weight_decay)
    kept = x.detach().clone()
    kept_loss = torch.full((b,), float("inf"), device=param.device)
    kept_err = torch.zeros(b, device=param.device)
    active = torch.ones(b, dtype=torch.bool, device=param.device)
    done = torch.zeros(b, dtype=torch.bool, device=param.device)
    used = torch.zeros(b, dtype=torch.long, device=param.device)
    view = (b,) + (1,) * (param.ndim - 1)
    for step in range(steps + 1):
        joints = forward(x)
        loss, finished, max_err = objective.evaluate(joints)
        value = loss.detach()
        finished = finished if config.early_stop else torch.zeros_like(finished)
        take = active & (finished | (value < kept_loss) | torch.tensor(not keep_best, device=x.device))
        kept = torch.where(take.view(view), x.detach(), kept)
        kept_loss = torch.where(take, value, kept_loss)
        kept_err = torch.where(take, max_err, kept_err)
        done = done | (active & finished)
        active = active & ~finished
        if step == steps or not bool(active.any()):
            break
        optimizer.zero_grad(set_to_none=True)
        (loss * active).sum().backward()
        optimizer.step()
        used = used + active.long()
        if not bool(active.all()):
            with torch.no_grad():
                x.copy_(torch.where(active.view(view), x, kept))
    return EditOutcome(param=kept, steps=used, done=done, loss=kept_loss, max_error=kept_err)
