"""Logits editing (ControlMM §3.3, "Logit Optimization" in v2): optimise the logits of one masked-decoding
iteration so that the motion they imply meets the objective, before tokens are sampled from them.

At decoding iteration k, with logits L (B, N, K) for every position, the masked positions (being
predicted now) and the positions already committed (their ids fixed):

    repeat (at most ``logits_steps`` times, a fresh AdamW per iteration, lr 0.06, betas (0.5, 0.9)):
        g ~ Gumbel;  p = softmax(L / tau + g)                          (B, N, K)
        e = p C_0 at masked positions, C_0[id] at committed ones, 0 at pads  (B, N, code_dim)
        joints = R(denorm(decoder(e)))  -> objective -> gradient step on L

``p C_0`` is the dual-space expectation (DCSE/DES): the same soft token choice is an expectation over
the base codebook C_0 for the frozen decoder. Unlike the released code, committed positions enter with
their own (hard) codes: this decoder feeds the transformer hard ids, so the estimate is exactly the
motion the committed tokens will produce, and editing only moves the tokens still to be sampled.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import torch

from controlmm.editing.objective import Objective
from controlmm.editing.optimize import EditOutcome, optimize
from controlmm.editing.presets import EditingConfig
from controlmm.models.layers import gumbel_noise


def soft_latent(
    logits: torch.Tensor,
    codebook: torch.Tensor,
    editable: torch.Tensor,
    fixed: torch.Tensor,
    temperature: float = 1.0,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Decoder input (B, N, code_dim): Gumbel-softmax expectation p C_0 where ``editable``, else ``fixed``."""
    p = torch.softmax(logits / temperature + gumbel_noise(logits, generator), dim=-1)
    return torch.where(editable[..., None], p @ codebook, fixed)


def logits_editing(
    logits: torch.Tensor,
    editable: torch.Tensor,
    fixed: torch.Tensor,
    codebook: torch.Tensor,
    decode: Callable[[torch.Tensor], torch.Tensor],
    objective: Objective,
    config: EditingConfig,
    generator: torch.Generator | None = None,
) -> EditOutcome:
    """Edit the logits (B, N, K) of one decoding iteration; returns the edited logits and the steps used.

    Args:
        logits: this iteration's logits (not modified).
        editable: (B, N) bool, the masked positions being predicted.
        fixed: (B, N, code_dim) latent of the other positions (committed codes; zeros at pads).
        codebook: (K, code_dim) the base-layer codebook C_0.
        decode: latent (B, N, code_dim) -> joints (B, T, 22, 3), differentiable.
        objective: loss terms and the stopping rule.
        config: ``logits_steps``, optimiser, temperature.
    """

    def forward(x: torch.Tensor) -> torch.Tensor:
        return decode(soft_latent(x, codebook, editable, fixed, config.temperature, generator))

    return optimize(
        logits,
        forward,
        objective,
        config.logits_steps,
        replace(config, lr=config.logits_lr),
        keep_best=False,
        patience=config.logits_patience,
    )
