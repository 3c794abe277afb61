"""Residual transformer: predicts RVQ layer q from layers 0..q-1 (MoMask ``ResidualTransformer``).

Vocabulary per layer: ``nb_code`` codes plus ``pad_id = nb_code``. Shared and tied weights (the
released ``..._sw`` model, separate codebooks)::

    token_embed_weight_       (1, K+1, code_dim)   E_0            (embeds base-layer ids)
    embed_proj_shared_weight  (Q-2, K+1, code_dim) E_1..E_{Q-2} = P_1..P_{Q-2}  (tied)
    output_proj_weight_       (1, K+1, code_dim)   P_{Q-1}        (projects the last layer)

Forward for layer q (1 <= q <= Q-1)::

    x      = PE(poseEmbedding(sum_{j<q} E_j[ids_j]))   (N, B, D)
    h_0    = [cond_emb(LN(text)) ; quant_emb(one_hot(q, Q)) ; x]
    h      = output_process(layers(h_0)[2:])            (B, N, code_dim)
    logits = h @ P_q^T                                  (B, N, K+1), no bias

Training draws q per sample with q = round((1 - cos(pi u / 2)) (Q - 2)) + 1 and applies
cross-entropy on layer-q ids (pads ignored); the text is dropped with probability 0.2.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.models.config import ResidualConfig
from controlmm.models.layers import (
    InputProcess,
    LayerHook,
    OutputProcess,
    PositionalEncoding,
    drop_condition,
    init_weights,
    lengths_to_mask,
    pool_text_tokens,
    run_layers,
    transformer_trunk,
)
from controlmm.models.mask_transformer import token_loss_and_accuracy


class ResidualTransformer(nn.Module):
    def __init__(self, cfg: ResidualConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.pad_id = cfg.pad_id
        q, k1, d = cfg.num_quantizers, cfg.nb_code + 1, cfg.code_dim
        self.input_process = InputProcess(cfg.code_dim, cfg.latent_dim)
        self.position_enc = PositionalEncoding(cfg.latent_dim, cfg.dropout, cfg.max_len)
        self.seqTransEncoder = transformer_trunk(
            cfg.latent_dim, cfg.num_heads, cfg.ff_size, cfg.dropout, cfg.num_layers
        )
        self.quant_emb = nn.Linear(q, cfg.latent_dim)
        self.text_norm = nn.LayerNorm(cfg.text_dim) if cfg.text_norm else nn.Identity()
        self.cond_emb = nn.Linear(cfg.text_dim, cfg.latent_dim)
        self.output_process = OutputProcess(cfg.code_dim, cfg.latent_dim)
        self.embed_proj_shared_weight = nn.Parameter(torch.normal(0.0, 0.02, size=(q - 2, k1, d)))
        self.token_embed_weight_ = nn.Parameter(torch.normal(0.0, 0.02, size=(1, k1, d)))
        self.output_proj_weight_ = nn.Parameter(torch.normal(0.0, 0.02, size=(1, k1, d)))
        self.apply(init_weights)

    @property
    def token_embed_weight(self) -> torch.Tensor:
        """E_0..E_{Q-2}: (Q-1, K+1, code_dim); E_j embeds the ids of layer j."""
        return torch.cat([self.token_embed_weight_, self.embed_proj_shared_weight], dim=0)

    @property
    def output_proj_weight(self) -> torch.Tensor:
        """P_1..P_{Q-1}: (Q-1, K+1, code_dim); P_q projects to layer q's logits (row q-1)."""
        return torch.cat([self.embed_proj_shared_weight, self.output_proj_weight_], dim=0)

    def mask_cond(self, cond: torch.Tensor, force_mask: bool = False) -> torch.Tensor:
        if force_mask:
            return torch.zeros_like(cond)
        if self.training and self.cfg.cond_drop_prob > 0:
            return drop_condition(cond, self.cfg.cond_drop_prob)
        return cond

    def history(self, ids: torch.Tensor, q: int) -> torch.Tensor:
        """sum_{j<q} E_j[ids_j]: ids (B, N, >= q) with pads as pad_id -> (B, N, code_dim)."""
        emb = self.token_embed_weight
        out = torch.zeros(ids.shape[:-1] + (emb.shape[-1],), dtype=emb.dtype, device=emb.device)
        for j in range(q):
            out = out + F.embedding(ids[..., j], emb[j])
        return out

    def forward(
        self,
        history: torch.Tensor,
        q: torch.Tensor,
        cond: torch.Tensor,
        padding_mask: torch.Tensor,
        force_mask: bool = False,
        hook: LayerHook | None = None,
    ) -> torch.Tensor:
        """Logits (B, N, K+1) of layer q.

        Args:
            history: (B, N, code_dim) summed embeddings of the layers below q.
            q: (B,) long, the layer to predict, 1..Q-1.
            cond: (B, text_dim) text vectors, or text token states (B, L, text_dim) (zero rows pad),
                pooled into the sentence vector.
            padding_mask: (B, N) True at padded positions.
            hook: optional ``hook(i, h) -> h`` after encoder layer i.
        """
        if cond.ndim == 3:
            cond = pool_text_tokens(cond)
        x = self.position_enc(self.input_process(history))
        q_emb = self.quant_emb(F.one_hot(q, self.cfg.num_quantizers).to(x.dtype))[None]
        c = self.cond_emb(self.text_norm(self.mask_cond(cond, force_mask)))[None]
        h = torch.cat([c, q_emb, x], dim=0)
        mask = torch.cat([torch.zeros_like(padding_mask[:, :2]), padding_mask], dim=1)
        h = self.output_process(run_layers(self.seqTransEncoder.layers, h, mask, hook)[2:])
        proj = self.output_proj_weight[q - 1]  # (B, K+1, code_dim)
        return torch.einsum("bnc,bkc->bnk", h, proj)

    def cfg_logits(
        self, history: torch.Tensor, q: int, cond: torch.Tensor, padding_mask: torch.Tensor, scale: float
    ) -> torch.Tensor:
        """Classifier-free-guided logits (B, N, K+1) of layer ``q`` (both passes in one batch)."""
        b = cond.shape[0]
        if scale == 1.0:
            return self(
                history, torch.full((b,), q, dtype=torch.long, device=cond.device), cond, padding_mask
            )
        qs = torch.full((2 * b,), q, dtype=torch.long, device=cond.device)
        logits = self(
            torch.cat([history, history]),
            qs,
            torch.cat([cond, torch.zeros_like(cond)]),
            torch.cat([padding_mask, padding_mask]),
        )
        cond_l, uncond_l = logits[:b], logits[b:]
        return uncond_l + scale * (cond_l - uncond_l)

    def residual_loss(
        self,
        ids: torch.Tensor,
        cond: torch.Tensor,
        lengths: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Training objective on all-layer ids (B, N, Q) with token lengths (B,): (CE, accuracy)."""
        b, n, num_q = ids.shape
        valid = lengths_to_mask(lengths, n)
        ids = torch.where(valid[..., None], ids, self.pad_id)
        u = torch.rand(b, device=ids.device, generator=generator)
        q = torch.round((1.0 - torch.cos(u * math.pi * 0.5)) * (num_q - 2)).long() + 1
        emb = self.token_embed_weight  # (Q-1, K+1, D)
        per_layer = torch.stack([F.embedding(ids[..., j], emb[j]) for j in range(num_q - 1)], dim=-1)
        cumulative = per_layer.cumsum(dim=-1)  # (B, N, D, Q-1)
        rows = torch.arange(b, device=ids.device)
        history = cumulative[rows, :, :, q - 1]
        labels = ids[rows, :, q]
        logits = self(history, q, cond, ~valid)
        return token_loss_and_accuracy(logits, labels, ignore_index=self.pad_id)
