"""Building blocks shared by the masked and residual transformers (MoMask layout).

Tensors inside the transformers are **sequence-first** ``(S, B, D)`` as in the official code
(``nn.TransformerEncoderLayer`` with ``batch_first=False``); the public methods of the models take
and return batch-first tensors.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.errors import ControlMMError

LayerHook = Callable[[int, torch.Tensor], torch.Tensor]
"""``hook(i, x) -> x``: called after encoder layer ``i`` on its (S, B, D) output."""


class InputProcess(nn.Module):
    """Token embeddings (B, N, code_dim) -> (N, B, latent_dim) through ``poseEmbedding``."""

    def __init__(self, input_feats: int, latent_dim: int) -> None:
        super().__init__()
        self.poseEmbedding = nn.Linear(input_feats, latent_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.poseEmbedding(x.permute(1, 0, 2))


class PositionalEncoding(nn.Module):
    """Sinusoidal table ``pe`` (max_len, 1, d) added to (S, B, d) inputs, then dropout."""

    pe: torch.Tensor  # buffer (max_len, 1, d)

    def __init__(self, d_model: int, dropout: float, max_len: int) -> None:
        super().__init__()
        self.dropout = nn.Dropout(p=dropout)
        position = torch.arange(max_len, dtype=torch.float32)[:, None]
        div_term = torch.exp(
            torch.arange(0, d_model, 2, dtype=torch.float32) * (-math.log(10000.0) / d_model)
        )
        pe = torch.zeros(max_len, d_model)
        pe[:, 0::2] = torch.sin(position * div_term)
        pe[:, 1::2] = torch.cos(position * div_term)
        self.register_buffer("pe", pe[:, None, :])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.shape[0] > self.pe.shape[0]:
            raise ControlMMError(
                f"sequence of {x.shape[0]} tokens exceeds the model's max_len {self.pe.shape[0]}"
            )
        return self.dropout(x + self.pe[: x.shape[0]])


class OutputProcess(nn.Module):
    """Head: Linear -> GELU -> LayerNorm(eps 1e-12) -> Linear; (N, B, latent) -> (B, N, out_feats)."""

    def __init__(self, out_feats: int, latent_dim: int) -> None:
        super().__init__()
        self.dense = nn.Linear(latent_dim, latent_dim)
        self.LayerNorm = nn.LayerNorm(latent_dim, eps=1e-12)
        self.poseFinal = nn.Linear(latent_dim, out_feats)

    def forward(self, hidden: torch.Tensor) -> torch.Tensor:
        hidden = self.LayerNorm(F.gelu(self.dense(hidden)))
        return self.poseFinal(hidden).permute(1, 0, 2)


def transformer_trunk(
    latent_dim: int, num_heads: int, ff_size: int, dropout: float, num_layers: int
) -> nn.TransformerEncoder:
    """``num_layers`` post-LN GELU ``TransformerEncoderLayer``s, sequence-first, no final norm."""
    layer = nn.TransformerEncoderLayer(
        d_model=latent_dim, nhead=num_heads, dim_feedforward=ff_size, dropout=dropout, activation="gelu"
    )
    return nn.TransformerEncoder(layer, num_layers=num_layers, enable_nested_tensor=False)


def init_weights(module: nn.Module) -> None:
    """MoMask init: Linear/Embedding N(0, 0.02) with zero bias; LayerNorm (1, 0)."""
    if isinstance(module, (nn.Linear, nn.Embedding)):
        module.weight.data.normal_(mean=0.0, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            module.bias.data.zero_()
    elif isinstance(module, nn.LayerNorm):
        module.bias.data.zero_()
        module.weight.data.fill_(1.0)


def lengths_to_mask(lengths: torch.Tensor, max_len: int) -> torch.Tensor:
    """(B,) lengths -> (B, max_len) bool, True at valid (non-padded) positions."""
    return torch.arange(max_len, device=lengths.device)[None, :] < lengths[:, None]


def cosine_schedule(t: torch.Tensor) -> torch.Tensor:
    """Mask ratio gamma(t) = cos(pi t / 2) for t in [0, 1]."""
    return torch.cos(t * math.pi * 0.5)


def top_k_filter(logits: torch.Tensor, thres: float = 0.9) -> torch.Tensor:
    """Keep the ceil((1 - thres) * K) largest logits of the last axis, -inf elsewhere."""
    k = max(1, math.ceil((1.0 - thres) * logits.shape[-1]))
    values, index = logits.topk(k, dim=-1)
    return torch.full_like(logits, float("-inf")).scatter_(-1, index, values)


def gumbel_noise(like: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Standard Gumbel noise of the shape/dtype/device of ``like``."""
    u = torch.rand(like.shape, generator=generator, device=like.device, dtype=like.dtype)
    return -torch.log((-torch.log(u.clamp(min=1e-20))).clamp(min=1e-20))


def apply_layer(
    layer: nn.Module, x: torch.Tensor, padding_mask: torch.Tensor, attn_mask: torch.Tensor | None = None
) -> torch.Tensor:
    """One encoder layer on (S, B, D) ``x``: with the key-padding mask (B, S), or with ``attn_mask``
    (B * heads, S, S), an additive mask that already holds the padding."""
    return layer(x, src_key_padding_mask=padding_mask) if attn_mask is None else layer(x, src_mask=attn_mask)


def run_layers(
    layers: nn.ModuleList,
    x: torch.Tensor,
    padding_mask: torch.Tensor,
    hook: LayerHook | None = None,
    attn_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Run encoder layers one by one on (S, B, D) ``x``.

    ``padding_mask`` (B, S) is True at padded positions. ``hook(i, x) -> x``, when given, is called
    after layer ``i`` (the motion control model adds its zero-linear residuals there). ``attn_mask``:
    see :func:`apply_layer` (:class:`~controlmm.models.relative_position.RelativePositionBias`).
    """
    for i, layer in enumerate(layers):
        x = apply_layer(layer, x, padding_mask, attn_mask)
        if hook is not None:
            x = hook(i, x)
    return x


def text_token_padding(states: torch.Tensor) -> torch.Tensor:
    """Token states (B, L, dim), all-zero rows padding -> (B, L) bool, True at padding."""
    return states.abs().amax(dim=-1) == 0


def trim_text_tokens(states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Drop the trailing columns that are padding in every row of (B, L, dim) (at least one is kept);
    returns the trimmed states (B, L', dim) and their padding (B, L') (True at padding)."""
    padding = text_token_padding(states)
    used = int((~padding).sum(dim=1).max().clamp(min=1))
    return states[:, :used], padding[:, :used]


def pool_text_tokens(states: torch.Tensor) -> torch.Tensor:
    """Token states (B, L, dim) -> sentence vectors (B, dim): mean over non-padding rows, L2-normalised
    (MiniLM's own pooling, so the result equals its sentence vector); all-padding rows give 0."""
    keep = (~text_token_padding(states)).to(states.dtype)[..., None]
    mean = (states * keep).sum(dim=1) / keep.sum(dim=1).clamp(min=1)
    return F.normalize(mean, dim=-1)


def zero_samples(x: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
    """``x`` (B, ...) with the entries where ``keep`` (its leading dims, e.g. (B,) or (B, L)) is 0 / False
    set to zero."""
    return x * keep.to(x.dtype).reshape(*keep.shape, *([1] * (x.ndim - keep.ndim)))


def drop_text_tokens(states: torch.Tensor, drop_prob: float) -> torch.Tensor:
    """Word dropout on text token states (B, L, dim): each row zeroed with probability ``drop_prob`` (a
    zero row is padding, see :func:`text_token_padding`)."""
    keep = torch.bernoulli(torch.full(states.shape[:2], 1.0 - drop_prob, device=states.device))
    return zero_samples(states, keep)


def drop_condition(cond: torch.Tensor, drop_prob: float) -> torch.Tensor:
    """Classifier-free-guidance training: zero each sample's text (B, ...) with probability ``drop_prob``."""
    keep = torch.bernoulli(torch.full((cond.shape[0],), 1.0 - drop_prob, device=cond.device))
    return zero_samples(cond, keep)
