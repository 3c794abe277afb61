"""Text-conditioned masked transformer over base-layer motion tokens (MoMask ``MaskTransformer``).

Vocabulary: ``nb_code`` codes, then ``mask_id = nb_code`` and ``pad_id = nb_code + 1``.

Forward pass (one condition, sequence-first inside, as the official module)::

    e      = token_emb(ids)                 (B, N, code_dim)   or given soft embeddings
    x      = PE(poseEmbedding(e))           (N, B, D)
    c      = cond_emb(LN(text or 0))        (1, B, D)          text zeroed for the unconditional pass;
                                                                LN only with cfg.text_norm; with text
                                                                token states (B, L, text_dim): (C, B, D),
                                                                with cfg.pooled_row one more row first:
                                                                pooled_emb(LN(pooled states))
    h_0    = [c ; x]                        (C+N, B, D)        C = 1 for a sentence vector
    h_L    = layers(h_0)                    8 post-LN GELU TransformerEncoderLayers (paper preset);
                                                                with cfg.relative_positions a learned
                                                                bias per token offset on the attention
    logits = output_process(h_L[C:])        (B, N, nb_code)    no logits for mask/pad

Training (``masked_loss``): cosine mask ratio, BERT corruption (10% random code, then 88% of the
rest [MASK]), cross-entropy on masked positions, 10% condition dropout (classifier-free guidance);
with token states and ``cfg.token_drop_prob``, word dropout of single token states first.

The pieces are separate methods so that the motion control model can reuse them: ``embed`` (h_0 and the
key-padding mask), ``run_layers`` with a per-layer hook, ``head`` (logits), ``forward`` and
``cfg_logits`` (classifier-free guidance: l_u + s (l_c - l_u)).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.models.config import TransformerConfig
from controlmm.models.layers import (
    InputProcess,
    LayerHook,
    OutputProcess,
    PositionalEncoding,
    cosine_schedule,
    drop_condition,
    drop_text_tokens,
    init_weights,
    lengths_to_mask,
    pool_text_tokens,
    run_layers,
    transformer_trunk,
    trim_text_tokens,
)
from controlmm.models.relative_position import RelativePositionBias


class MaskTransformer(nn.Module):
    def __init__(self, cfg: TransformerConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.mask_id, self.pad_id = cfg.mask_id, cfg.pad_id
        self.input_process = InputProcess(cfg.code_dim, cfg.latent_dim)
        self.position_enc = PositionalEncoding(cfg.latent_dim, cfg.dropout, cfg.max_len)
        self.seqTransEncoder = transformer_trunk(
            cfg.latent_dim, cfg.num_heads, cfg.ff_size, cfg.dropout, cfg.num_layers
        )
        self.text_norm = nn.LayerNorm(cfg.text_dim) if cfg.text_norm else nn.Identity()
        self.cond_emb = nn.Linear(cfg.text_dim, cfg.latent_dim)
        if cfg.pooled_row:
            self.pooled_norm = nn.LayerNorm(cfg.text_dim)
            self.pooled_emb = nn.Linear(cfg.text_dim, cfg.latent_dim)
        self.output_process = OutputProcess(cfg.nb_code, cfg.latent_dim)
        self.token_emb = nn.Embedding(cfg.nb_code + 2, cfg.code_dim)
        self.apply(init_weights)
        self.relative_bias = (
            RelativePositionBias(cfg.num_heads, cfg.relative_positions) if cfg.relative_positions else None
        )  # zero table: starts as MoMask

    # -- pieces -----------------------------------------------------------------------------------
    def mask_cond(self, cond: torch.Tensor, force_mask: bool = False) -> torch.Tensor:
        """Zero the text vector for the unconditional pass; while training, drop single token states
        (``cfg.token_drop_prob``, token states only), then whole texts (``cfg.cond_drop_prob``) at random."""
        if force_mask:
            return torch.zeros_like(cond)
        if self.training and cond.ndim == 3 and self.cfg.token_drop_prob > 0:
            cond = drop_text_tokens(cond, self.cfg.token_drop_prob)
        if self.training and self.cfg.cond_drop_prob > 0:
            return drop_condition(cond, self.cfg.cond_drop_prob)
        return cond

    def token_embeddings(self, tokens: torch.Tensor) -> torch.Tensor:
        """Ids (B, N) -> (B, N, code_dim); soft embeddings (B, N, code_dim) pass through."""
        return self.token_emb(tokens) if tokens.dtype in (torch.long, torch.int32, torch.int64) else tokens

    def embed(
        self, tokens: torch.Tensor, cond: torch.Tensor, padding_mask: torch.Tensor, force_mask: bool = False
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """h_0 = [condition rows ; PE(poseEmbedding(tokens))] (C+N, B, D) and its key-padding mask (B, C+N).

        Args:
            tokens: ids (B, N) or soft embeddings (B, N, code_dim).
            cond: text vectors (B, text_dim): one condition row (C = 1, MoMask); or text token states
                (B, L, text_dim) with all-zero rows as padding: one row per token (C <= L, padding
                masked; a dropped or unconditional text is all padding), plus with ``cfg.pooled_row``
                a first row for the pooled sentence vector (zero for a dropped text, never masked).
            padding_mask: (B, N) True at padded positions.
        """
        x = self.position_enc(self.input_process(self.token_embeddings(tokens)))
        cond = self.mask_cond(cond, force_mask)
        if cond.ndim == 2:
            c = self.cond_emb(self.text_norm(cond))[None]
            c_pad = torch.zeros_like(padding_mask[:, :1])
        else:
            pooled = pool_text_tokens(cond) if self.cfg.pooled_row else None
            cond, c_pad = trim_text_tokens(cond)
            c = self.cond_emb(self.text_norm(cond)).transpose(0, 1)
            if pooled is not None:
                c = torch.cat([self.pooled_emb(self.pooled_norm(pooled))[None], c], dim=0)
                c_pad = torch.cat([torch.zeros_like(c_pad[:, :1]), c_pad], dim=1)
        return torch.cat([c, x], dim=0), torch.cat([c_pad, padding_mask], dim=1)

    def attention_mask(self, mask: torch.Tensor, num_tokens: int, dtype: torch.dtype) -> torch.Tensor | None:
        """The additive attention mask (B * heads, C+N, C+N) of the relative position bias for the
        key-padding mask (B, C+N) of :meth:`embed` and N = ``num_tokens``; None without the bias."""
        if self.relative_bias is None:
            return None
        return self.relative_bias.attention_mask(mask, num_tokens, dtype)

    def run_layers(
        self,
        h: torch.Tensor,
        mask: torch.Tensor,
        hook: LayerHook | None = None,
        num_tokens: int | None = None,
    ) -> torch.Tensor:
        """The encoder layers on (C+N, B, D); ``hook(i, h) -> h`` runs after layer i. ``num_tokens`` = N
        (the motion rows) is needed with the relative position bias."""
        if self.relative_bias is not None and num_tokens is None:
            raise ValueError("run_layers needs num_tokens with the relative position bias")
        attn = self.attention_mask(mask, num_tokens, h.dtype) if num_tokens is not None else None
        return run_layers(self.seqTransEncoder.layers, h, mask, hook, attn)

    def head(self, h: torch.Tensor, num_tokens: int) -> torch.Tensor:
        """Final hidden states (C+N, B, D) -> logits (B, N, nb_code) of the last ``num_tokens`` = N rows
        (the condition rows dropped)."""
        return self.output_process(h[h.shape[0] - num_tokens :])

    # -- passes -----------------------------------------------------------------------------------
    def forward(
        self, tokens: torch.Tensor, cond: torch.Tensor, padding_mask: torch.Tensor, force_mask: bool = False
    ) -> torch.Tensor:
        """Logits (B, N, nb_code) for ids or soft embeddings ``tokens``; see :meth:`embed`."""
        h, mask = self.embed(tokens, cond, padding_mask, force_mask)
        n = padding_mask.shape[1]
        return self.head(self.run_layers(h, mask, num_tokens=n), n)

    def cfg_logits(
        self, tokens: torch.Tensor, cond: torch.Tensor, padding_mask: torch.Tensor, scale: float
    ) -> torch.Tensor:
        """Classifier-free guidance l_u + scale (l_c - l_u), both passes in one batch; (B, N, nb_code)."""
        if scale == 1.0:
            return self(tokens, cond, padding_mask)
        b = cond.shape[0]
        both = torch.cat([cond, torch.zeros_like(cond)], dim=0)
        logits = self(
            torch.cat([tokens, tokens], dim=0), both, torch.cat([padding_mask, padding_mask], dim=0)
        )
        cond_l, uncond_l = logits[:b], logits[b:]
        return uncond_l + scale * (cond_l - uncond_l)

    def masked_loss(
        self,
        ids: torch.Tensor,
        cond: torch.Tensor,
        lengths: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """MoMask training objective on base-layer ids (B, N) with token lengths (B,).

        Returns (cross-entropy on masked positions, accuracy on masked positions).
        """
        b, n = ids.shape
        device = ids.device
        valid = lengths_to_mask(lengths, n)
        ids = torch.where(valid, ids, self.pad_id)
        ratio = cosine_schedule(torch.rand(b, device=device, generator=generator))
        num_masked = (n * ratio).round().clamp(min=1)
        order = torch.rand(b, n, device=device, generator=generator).argsort(dim=-1)
        mask = (order < num_masked[:, None]) & valid
        labels = torch.where(mask, ids, self.mask_id)  # mask_id doubles as the ignore label
        x_ids = ids.clone()
        random_sub = mask & (torch.rand(b, n, device=device, generator=generator) < 0.1)
        random_ids = torch.randint(0, self.cfg.nb_code, (b, n), device=device, generator=generator)
        x_ids = torch.where(random_sub, random_ids, x_ids)
        mask_sub = mask & ~random_sub & (torch.rand(b, n, device=device, generator=generator) < 0.88)
        x_ids = torch.where(mask_sub, self.mask_id, x_ids)
        logits = self(x_ids, cond, ~valid)
        return token_loss_and_accuracy(logits, labels, ignore_index=self.mask_id)


def token_loss_and_accuracy(
    logits: torch.Tensor, labels: torch.Tensor, ignore_index: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Cross-entropy of logits (B, N, K) against labels (B, N) ignoring ``ignore_index``; and accuracy."""
    loss = F.cross_entropy(logits.permute(0, 2, 1), labels, ignore_index=ignore_index)
    keep = labels != ignore_index
    correct = (logits.argmax(-1) == labels) & keep
    acc = correct.sum().float() / keep.sum().clamp(min=1).float()
    return loss, acc
