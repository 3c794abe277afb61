"""Residual layers on top of the base ids (MoMask ``ResidualTransformer.generate``).

For q = 1..Q-1: history += E_{q-1}[ids_{q-1}]; logits_q = CFG (scale 5) of the residual transformer;
top-k 0.9; Gumbel-argmax at temperature tau (MoMask: 1; MaskControl: 1e-8, i.e. argmax; 0 here = argmax).
Unlike MoMask, the pad class is never sampled at valid positions (MoMask could draw it and then decode a
zero vector there). Pads keep ``pad_id`` in the history and -1 in the returned ids.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from controlmm.generate.masked_decoding import sample_ids
from controlmm.models.layers import lengths_to_mask, top_k_filter
from controlmm.models.residual_transformer import ResidualTransformer


@torch.no_grad()
def residual_decode(
    residual: ResidualTransformer,
    base_ids: torch.Tensor,
    cond: torch.Tensor,
    token_lengths: torch.Tensor,
    cfg_scale: float = 5.0,
    temperature: float = 1.0,
    topk: float | None = 0.9,
    generator: torch.Generator | None = None,
    num_layers: int | None = None,
    logits_hook: Callable[[torch.Tensor, int], torch.Tensor] | None = None,
) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """Complete base ids (B, N) (-1 at pads) with residual layers.

    Returns:
        ids (B, N, 1 + layers) long with -1 at pads, and the per-layer logits [(B, N, K+1)] of layers
        1..layers (after ``logits_hook(logits, q)``, if given).
    """
    device = cond.device
    n = base_ids.shape[1]
    padding = ~lengths_to_mask(token_lengths.to(device), n)
    pad_id, nb_code = residual.pad_id, residual.cfg.nb_code
    layers = residual.cfg.num_quantizers - 1 if num_layers is None else num_layers
    current = torch.where(padding, pad_id, base_ids)
    all_ids, all_logits = [current], []
    embed = residual.token_embed_weight
    history = torch.zeros(base_ids.shape + (residual.cfg.code_dim,), device=device)
    for q in range(1, layers + 1):
        history = history + torch.nn.functional.embedding(current, embed[q - 1])
        logits = residual.cfg_logits(history, q, cond, padding, cfg_scale)
        if logits_hook is not None:
            logits = logits_hook(logits, q)
        all_logits.append(logits)
        codes = logits[..., :nb_code]
        filtered = top_k_filter(codes, topk) if topk is not None else codes
        pred = sample_ids(filtered, temperature, True, generator)
        current = torch.where(padding, pad_id, pred)
        all_ids.append(current)
    ids = torch.stack(all_ids, dim=-1)
    return torch.where(ids == pad_id, -1, ids), all_logits
