"""Codebook editing (ControlMM §3.3, "embedding editing" in the code): optimise the decoder input.

After the base and residual layers are decoded, the latent e = sum_q C_q[id_q] (B, N, code_dim), the
sum of the RVQ layers' code vectors at every token position, becomes a free per-sample tensor and is
optimised (at most ``codebook_steps`` AdamW steps, lr 0.06, betas (0.5, 0.9)) against the objective on
R(denorm(decoder(e))). The shared codebooks themselves never change: despite its name, the official code
edits this per-sample latent, not the codebook entries. The latent with the lowest loss is kept; a
sample stops as soon as it meets the stopping rule.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from controlmm.editing.objective import Objective
from controlmm.editing.optimize import EditOutcome, optimize, optimize_lbfgs
from controlmm.editing.presets import EditingConfig


def codebook_editing(
    latent: torch.Tensor,
    decode: Callable[[torch.Tensor], torch.Tensor],
    objective: Objective,
    config: EditingConfig,
    admissible: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> EditOutcome:
    """Edit the decoder latent (B, N, code_dim); returns the edited latent and the steps used.

    Args:
        latent: the decoded tokens' latent (not modified).
        decode: latent -> joints (B, T, 22, 3), differentiable.
        objective: loss terms and the stopping rule.
        config: ``codebook_steps`` and the optimiser.
        admissible: joints -> (B,) bool, the states that may be kept (see :func:`optimize`).
    """
    if config.codebook_optimizer == "lbfgs":
        return optimize_lbfgs(latent, decode, objective, config.codebook_steps, config, admissible=admissible)
    return optimize(
        latent, decode, objective, config.codebook_steps, config, keep_best=True, admissible=admissible
    )
