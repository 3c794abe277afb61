"""Iterative masked decoding of the base token layer (MoMask ``MaskTransformer.generate``).

Per sample with L valid tokens (pads beyond L): start from all [MASK]; at iteration k of K
(t_k = k / (K - 1)) re-mask the n_k = max(1, round(cos(pi t_k / 2) L)) lowest-scoring positions, predict
logits with classifier-free guidance, keep the top-k logits (threshold 0.9: ceil(0.1 * 512) = 52), sample
the masked positions (categorical at temperature tau, or Gumbel-argmax), and score each newly sampled
token by its probability under the unfiltered logits. Positions left unmasked at step k get score
1e5 and are never re-masked. For L = 49 and K = 10: n = 49, 48, 46, 42, 38, 31, 24, 17, 9, 1.

Extension points for the control model and editing:

- ``logits_fn(ids, state) -> (B, N, K)`` replaces the plain CFG transformer (e.g. the motion
  control model);
- ``logits_hook(logits, state) -> logits`` edits the logits of each iteration before sampling
  (logits editing); the final, possibly edited, logits are returned with the ids.
- ``state.previous_logits`` (the last iteration's edited logits) lets a ``logits_fn`` feed soft token
  embeddings (softmax(L) @ token_emb) instead of ids, as MaskControl's decoding does.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from controlmm.models.layers import gumbel_noise, lengths_to_mask, top_k_filter
from controlmm.models.mask_transformer import MaskTransformer


@dataclass(frozen=True)
class DecodeOptions:
    """Sampling settings of the base layer (MoMask defaults)."""

    iterations: int = 10
    cfg_scale: float = 4.0
    temperature: float = 1.0  # 0 = greedy (argmax)
    topk: float | None = 0.9  # keep ceil((1 - topk) * K) logits; None = no filtering
    gumbel: bool = False  # Gumbel-argmax sampling instead of categorical


@dataclass
class DecodeState:
    """What hooks see at iteration ``step``: current ids (masked positions hold mask_id)."""

    step: int
    ids: torch.Tensor  # (B, N) long
    is_mask: torch.Tensor  # (B, N) bool, positions being predicted now
    padding_mask: torch.Tensor  # (B, N) bool, True at pads
    cond: torch.Tensor  # (B, text_dim)
    previous_logits: torch.Tensor | None = None  # (B, N, K) logits of the previous iteration (after the hook)


@dataclass
class BaseDecoding:
    ids: torch.Tensor  # (B, N) long, -1 at pads
    logits: torch.Tensor  # (B, N, K) logits of the last iteration (after the hook)
    token_lengths: torch.Tensor  # (B,)


def mask_counts(token_lengths: torch.Tensor, iterations: int) -> list[torch.Tensor]:
    """Number of masked tokens per iteration: max(1, round(cos(pi t_k / 2) L)), t_k = k / (K - 1)."""
    steps = torch.linspace(0, 1, iterations) if iterations > 1 else torch.zeros(1)
    return [
        torch.round(torch.cos(t * math.pi * 0.5) * token_lengths.float()).clamp(min=1).long() for t in steps
    ]


def sample_ids(
    logits: torch.Tensor, temperature: float, gumbel: bool, generator: torch.Generator | None
) -> torch.Tensor:
    """Draw ids (B, N) from logits (B, N, K) (-inf entries are never drawn)."""
    if temperature <= 0:
        return logits.argmax(-1)
    if gumbel:
        return (logits / temperature + gumbel_noise(logits, generator)).argmax(-1)
    probs = torch.softmax(logits / temperature, dim=-1)
    flat = probs.reshape(-1, probs.shape[-1])
    return torch.multinomial(flat, 1, generator=generator).view(probs.shape[:-1])


LogitsFn = Callable[[torch.Tensor, DecodeState], torch.Tensor]
LogitsHook = Callable[[torch.Tensor, DecodeState], torch.Tensor]


@torch.no_grad()
def masked_decode(
    transformer: MaskTransformer,
    cond: torch.Tensor,
    token_lengths: torch.Tensor,
    options: DecodeOptions = DecodeOptions(),
    generator: torch.Generator | None = None,
    logits_fn: LogitsFn | None = None,
    logits_hook: LogitsHook | None = None,
) -> BaseDecoding:
    """Decode base-layer ids for text vectors ``cond`` (B, text_dim) and lengths (B,) in tokens."""
    device = cond.device
    token_lengths = token_lengths.to(device)
    n = int(token_lengths.max())
    padding = ~lengths_to_mask(token_lengths, n)
    mask_id, pad_id = transformer.mask_id, transformer.pad_id
    ids = torch.where(padding, pad_id, mask_id)
    scores = torch.where(padding, 1e5, 0.0)
    logits = None
    for k, count in enumerate(mask_counts(token_lengths, options.iterations)):
        ranks = scores.argsort(dim=1, stable=True).argsort(dim=1, stable=True)
        is_mask = ranks < count.to(device)[:, None]
        ids = torch.where(is_mask, mask_id, ids)
        state = DecodeState(
            step=k, ids=ids, is_mask=is_mask, padding_mask=padding, cond=cond, previous_logits=logits
        )
        if logits_fn is not None:
            logits = logits_fn(ids, state)
        else:
            logits = transformer.cfg_logits(ids, cond, padding, options.cfg_scale)
        if logits_hook is not None:
            logits = logits_hook(logits, state)
        filtered = top_k_filter(logits, options.topk) if options.topk is not None else logits
        pred = sample_ids(filtered, options.temperature, options.gumbel, generator)
        ids = torch.where(is_mask, pred, ids)
        probs = torch.softmax(logits, dim=-1)
        scores = probs.gather(-1, pred[..., None]).squeeze(-1).masked_fill(~is_mask, 1e5)
    if logits is None:  # mask_counts gives at least one iteration
        raise RuntimeError("masked decoding ran no iteration")
    ids = torch.where(padding, -1, ids)
    return BaseDecoding(ids=ids, logits=logits, token_lengths=token_lengths)
