"""The optimisation loop shared by logits editing and codebook editing.

A per-sample tensor ``param`` (B, ...) is optimised with a fresh AdamW (or L-BFGS;
:mod:`controlmm.editing.optimizers`) against an
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
from controlmm.editing.optimizers import LBFGS, AdamW
from controlmm.editing.presets import EditingConfig


@dataclass
class EditOutcome:
    """Per-sample result of one editing run."""

    param: torch.Tensor  # (B, ...) the edited tensor (detached)
    steps: torch.Tensor  # (B,) long, optimiser steps each sample took
    done: torch.Tensor  # (B,) bool, met the stopping criterion
    loss: torch.Tensor  # (B,) objective of the returned state (as last evaluated)
    max_error: torch.Tensor  # (B,) worst constraint error (m) of the returned state


def optimize(
    param: torch.Tensor,
    forward: Callable[[torch.Tensor], torch.Tensor],
    objective: Objective,
    steps: int,
    config: EditingConfig,
    keep_best: bool = True,
    patience: int = 0,
    min_improvement: float = 0.02,
    admissible: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> EditOutcome:
    """Minimise ``objective(forward(param))`` over ``param`` for at most ``steps`` AdamW steps.

    Args:
        param: (B, ...) initial value (not modified).
        forward: param -> joints (B, T, 22, 3), differentiable.
        objective: the loss and the stopping rule.
        steps: step budget (0: only evaluate).
        config: optimiser settings and whether to stop early.
        keep_best: return, for samples that never finish, the evaluated state with the lowest loss
            (codebook editing); otherwise the last state (logits editing, whose loss is noisy).
        patience: if > 0, a sample also stops (without counting as done) once its best loss has not
            improved by the fraction ``min_improvement`` for ``patience`` steps (a plateau).
        admissible: joints -> (B,) bool; when given, only admissible states are kept (a sample with
            none keeps ``param``), so a run that trades one term against another never returns a state
            that breaks what the caller must keep (the foot-contact run keeps the constraints met).
    """
    b = param.shape[0]
    x = param.detach().clone().requires_grad_(True)
    optimizer = AdamW(x, lr=config.lr, betas=config.betas, weight_decay=config.weight_decay)
    kept = x.detach().clone()
    kept_loss = torch.full((b,), float("inf"), device=param.device)
    kept_err = torch.zeros(b, device=param.device)
    active = torch.ones(b, dtype=torch.bool, device=param.device)
    done = torch.zeros(b, dtype=torch.bool, device=param.device)
    used = torch.zeros(b, dtype=torch.long, device=param.device)
    view = (b,) + (1,) * (param.ndim - 1)
    best = torch.full((b,), float("inf"), device=param.device)
    stale = torch.zeros(b, dtype=torch.long, device=param.device)
    for step in range(steps + 1):
        joints = forward(x)
        loss, finished, max_err = objective.evaluate(joints)
        value = loss.detach()
        finished = finished if config.early_stop else torch.zeros_like(finished)
        take = active & (finished | (value < kept_loss) | torch.tensor(not keep_best, device=x.device))
        if admissible is not None:
            with torch.no_grad():
                take = take & admissible(joints)
        kept = torch.where(take.view(view), x.detach(), kept)
        kept_loss = torch.where(take, value, kept_loss)
        kept_err = torch.where(take, max_err, kept_err)
        done = done | (active & finished)
        active = active & ~finished
        if patience > 0:
            better = value < best * (1.0 - min_improvement)
            best = torch.where(better, value, torch.minimum(best, value))
            stale = torch.where(better, torch.zeros_like(stale), stale + 1)
            active = active & (stale < patience)
        if step == steps or not bool(active.any()):
            break
        optimizer.zero_grad()
        (loss * active).sum().backward()
        optimizer.step()
        used = used + active.long()
        if not bool(active.all()):
            with torch.no_grad():
                x.copy_(torch.where(active.view(view), x, kept))
    return EditOutcome(param=kept, steps=used, done=done, loss=kept_loss, max_error=kept_err)


@dataclass
class _LbfgsState:
    """What the L-BFGS closure updates at every evaluation (per sample, like :class:`EditOutcome`)."""

    kept: torch.Tensor  # (B, ...) the best evaluated state
    kept_loss: torch.Tensor  # (B,) its loss
    kept_err: torch.Tensor  # (B,) its worst constraint error (m)
    done: torch.Tensor  # (B,) bool, met the stopping rule
    used: torch.Tensor  # (B,) long, evaluations counted as steps
    count: int = 0  # evaluations so far, the starting point included


def optimize_lbfgs(
    param: torch.Tensor,
    forward: Callable[[torch.Tensor], torch.Tensor],
    objective: Objective,
    evaluations: int,
    config: EditingConfig,
    chunk: int = 10,
    admissible: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> EditOutcome:
    """Minimise ``objective(forward(param))`` with L-BFGS (strong Wolfe line search), at most
    ``evaluations`` evaluations.

    The control loss is a smooth least-squares problem whose pelvis part is badly conditioned (the root
    trajectory integrates velocities and headings over the whole clip); a quasi-Newton method meets
    dense trajectories to millimetres where first-order steps stall at centimetres. Every evaluation
    (line-search trials included) counts as one step and is checked per sample: the best evaluated
    state of each sample is kept, and a sample that meets the stopping rule is frozen there. The
    optimiser runs in chunks of ``chunk`` iterations; it restarts (fresh curvature history) whenever
    samples drop out. A chunk that did not lower a sample's best loss (stalled: its line searches found
    no decrease) restarts the optimiser from the best state with a fresh curvature history; a sample
    that stalls again right after such a restart drops out (further chunks would repeat the same
    evaluations). Each sample's loss is divided by its initial value, so the first step's size does
    not depend on the units of the loss. ``admissible``: as in :func:`optimize`.
    """
    b = param.shape[0]
    view = (b,) + (1,) * (param.ndim - 1)
    device = param.device
    x = param.detach().clone().requires_grad_(True)
    active = torch.ones(b, dtype=torch.bool, device=device)  # still optimised (restarts drop the done ones)
    scale = torch.ones(b, device=device)  # 1 / initial loss: L-BFGS's first step is sized by the gradient
    state = _LbfgsState(
        kept=x.detach().clone(),
        kept_loss=torch.full((b,), float("inf"), device=device),
        kept_err=torch.zeros(b, device=device),
        done=torch.zeros(b, dtype=torch.bool, device=device),
        used=torch.zeros(b, dtype=torch.long, device=device),
    )

    def new_optimizer() -> LBFGS:
        return LBFGS(x, lr=1.0, max_iter=chunk, max_eval=chunk * 2, history_size=50)

    def closure() -> torch.Tensor:
        x.grad = None
        joints = forward(x)
        loss, finished, max_err = objective.evaluate(joints)
        value = loss.detach()
        finished = finished if config.early_stop else torch.zeros_like(finished)
        ok = torch.isfinite(value)
        # A line search may ask for more evaluations than the budget left: those are not steps.
        moving = active & ~state.done & (state.count <= evaluations)
        if state.count == 0:
            scale.copy_(1.0 / value.clamp(min=1e-12).nan_to_num(1.0))
        else:  # the first evaluation is the starting point, not a step
            state.used = state.used + moving.long()
        take = moving & ok & (finished | (value < state.kept_loss))
        if admissible is not None:
            with torch.no_grad():
                take = take & admissible(joints)
        state.kept = torch.where(take.view(view), x.detach(), state.kept)
        state.kept_loss = torch.where(take, value, state.kept_loss)
        state.kept_err = torch.where(take, max_err, state.kept_err)
        state.done = state.done | (moving & finished & ok)
        state.count += 1
        # samples done in this chunk stop moving; once all are, the zero gradient ends the L-BFGS step
        total = torch.where(active & ~state.done & ok, loss * scale, torch.zeros_like(loss)).sum()
        if total.requires_grad:
            total.backward()
        return total.detach()

    # Nothing is done yet, so the first pass of the loop keeps this optimiser and x.
    optimizer = new_optimizer()
    restarted = torch.zeros(b, dtype=torch.bool, device=device)  # restarted after a stall, last chunk
    while True:
        if bool((active & state.done).any()):
            active = active & ~state.done
            optimizer = new_optimizer()
            with torch.no_grad():
                x.copy_(torch.where(active.view(view), x, state.kept))
        if state.count == 0:
            with torch.enable_grad():
                closure()
            active = active & ~state.done
        if state.count > evaluations or not bool(active.any()):
            break
        before, best_before = state.count, state.kept_loss.clone()
        optimizer.max_eval = max(1, min(chunk * 2, evaluations + 1 - state.count))
        optimizer.step(closure)
        if state.count == before:  # converged to machine precision
            break
        # A sample whose best loss did not improve over a whole chunk has stalled: its line searches
        # found no decrease, and the next chunks would evaluate the same points again.
        stalled = active & ~state.done & ~(state.kept_loss < best_before)
        if bool(stalled.any()) and state.count <= evaluations:
            active = active & ~(stalled & restarted)  # stalled twice in a row: drop out
            restarted = stalled & active
            if not bool(active.any()):
                break
            optimizer = new_optimizer()
            with torch.no_grad():  # every active sample restarts from its best state
                x.copy_(state.kept)
        else:
            restarted = torch.zeros_like(active)
    return EditOutcome(
        param=state.kept,
        steps=state.used,
        done=state.done,
        loss=state.kept_loss,
        max_error=state.kept_err,
    )
