"""The motion control model: ControlMM's ControlNet branch on the frozen masked transformer.

Parameters (the official MaskControl ``ControlTransformer`` names; ``control.pt`` holds only these,
the frozen base stays in ``transformer.pt``)::

    seqTransEncoder_control   trainable copy of the base encoder layers (initialised = the base)
    encoder_control           the tokenizer's Encoder class: (B, C, 4N) -> (B, D, N), C = 6 or 36
    first_zero_linear         Linear(D, D), zero-initialised: control tokens added to h_0
    mid_zero_linear.{i}       Linear(D, D) per layer, zero-initialised: residuals into the base

Forward, one classifier-free-guidance branch (as the official MaskControl ``ControlTransformer``,
https://github.com/exitudio/MaskControl, including its non-standard wiring: the frozen base also
receives the control-augmented input h_0)::

    x_0 = [cond ; PE(poseEmbedding(tokens))]                (C+N, B, D)   frozen base modules, C = 1
                                                              (or the text token rows)
    c   = first_zero_linear(encoder_control(control_input))   (N, B, D)
    h_0 = x_0 + [0 ; c]                                       the condition rows get no control
    g_i = ControlLayer_i(g_{i-1}),  g_0 = h_0                 trainable branch
    b_i = BaseLayer_i(b_{i-1}) + mid_zero_linear_i(g_i),  b_0 = h_0
    logits = base head(b_L[C:])                               (B, N, K)

With every zero linear at zero, the logits are exactly the base model's.

Control input (ControlMM paper, appendix A.8, as the official code builds it): targets S (B, T, 22, 3),
mask sigma (B, T, 22) and the current motion estimate G (B, T, 22, 3) decoded from the tokens known so
far (masked positions take ``mask_emb_vq``, the mean of the base codebook). For the control joints J
(pelvis; or pelvis, feet, head, wrists): rel = (S - G) sigma, abs = S sigma, channels
[rel_J xyz ..., abs_J xyz ...].
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from controlmm.models.config import ModelConfig
from controlmm.models.layers import apply_layer, run_layers, transformer_trunk
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.models.model_dir import register_part
from controlmm.models.rvqvae import Encoder


class MotionControlModel(nn.Module):
    """The trainable control branch; the frozen base transformer is passed to each call."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        tr, tok, ctrl = cfg.transformer, cfg.tokenizer, cfg.control
        self.joint_ids = ctrl.joint_ids
        self.seqTransEncoder_control = transformer_trunk(
            tr.latent_dim, tr.num_heads, tr.ff_size, tr.dropout, tr.num_layers
        )
        self.encoder_control = Encoder(
            ctrl.channels,
            tr.latent_dim,
            tok.width,
            down_t=tok.down_t,
            stride_t=tok.stride_t,
            depth=tok.depth,
            growth=tok.dilation_growth_rate,
            dropout=ctrl.encoder_dropout,
        )
        self.first_zero_linear = zero_linear(tr.latent_dim)
        self.mid_zero_linear = nn.ModuleList(zero_linear(tr.latent_dim) for _ in range(tr.num_layers))

    def init_from_base(self, base: MaskTransformer) -> MotionControlModel:
        """Copy the base encoder layers into the control branch (done once, before training)."""
        self.seqTransEncoder_control.load_state_dict(copy.deepcopy(base.seqTransEncoder.state_dict()))
        return self

    def control_tokens(self, control_input: torch.Tensor) -> torch.Tensor:
        """(B, C, 4N) control input -> (N, B, D) zero-linear control tokens."""
        return self.first_zero_linear(self.encoder_control(control_input).permute(2, 0, 1))

    def forward(
        self,
        base: MaskTransformer,
        tokens: torch.Tensor,
        cond: torch.Tensor,
        padding_mask: torch.Tensor,
        control_input: torch.Tensor,
        force_mask: bool = False,
    ) -> torch.Tensor:
        """Logits (B, N, K) of the base transformer steered by the control branch.

        Args:
            base: the frozen masked transformer (its modules are used, never changed).
            tokens: ids (B, N) or soft token embeddings (B, N, code_dim).
            cond: text vectors (B, text_dim) or token states (B, L, text_dim) (zeros: unconditional).
            padding_mask: (B, N), True at pads.
            control_input: (B, C, 4N) from :func:`control_input`.
        """
        h, mask = base.embed(tokens, cond, padding_mask, force_mask)
        c = self.control_tokens(control_input)
        h = h + torch.cat([torch.zeros_like(h[: h.shape[0] - c.shape[0]]), c], dim=0)  # not on condition rows
        residuals = []
        g = h
        attn = base.attention_mask(mask, c.shape[0], h.dtype)  # the base's relative position bias, if any
        for layer, zero in zip(self.seqTransEncoder_control.layers, self.mid_zero_linear, strict=True):
            g = apply_layer(layer, g, mask, attn)
            residuals.append(zero(g))
        out = run_layers(base.seqTransEncoder.layers, h, mask, lambda i, x: x + residuals[i], attn)
        return base.head(out, c.shape[0])

    def cfg_logits(
        self,
        base: MaskTransformer,
        tokens: torch.Tensor,
        cond: torch.Tensor,
        padding_mask: torch.Tensor,
        control_input: torch.Tensor,
        scale: float,
    ) -> torch.Tensor:
        """Classifier-free guidance l_u + s (l_c - l_u); both passes see the control (official)."""
        if scale == 1.0:
            return self(base, tokens, cond, padding_mask, control_input)
        b = cond.shape[0]
        logits = self(
            base,
            torch.cat([tokens, tokens]),
            torch.cat([cond, torch.zeros_like(cond)]),
            torch.cat([padding_mask, padding_mask]),
            torch.cat([control_input, control_input]),
        )
        cond_l, uncond_l = logits[:b], logits[b:]
        return uncond_l + scale * (cond_l - uncond_l)


def zero_linear(dim: int) -> nn.Linear:
    layer = nn.Linear(dim, dim)
    nn.init.zeros_(layer.weight)
    nn.init.zeros_(layer.bias)
    return layer


def control_input(
    targets: torch.Tensor, mask: torch.Tensor, current: torch.Tensor, joint_ids: tuple[int, ...]
) -> torch.Tensor:
    """The control branch's input (B, 6 |J|, T) (the official ``encoder_control`` input).

    Args:
        targets: (B, T, 22, 3) target global joints (any value where not controlled).
        mask: (B, T, 22) bool, True where controlled.
        current: (B, T, 22, 3) current motion estimate.
        joint_ids: the joints the branch sees (``ControlConfig.joint_ids``).

    Returns:
        channels [rel_{j1} xyz, ..., rel_{jn} xyz, abs_{j1} xyz, ..., abs_{jn} xyz], channels-first.
    """
    sigma = mask[:, :, list(joint_ids), None].to(targets.dtype)
    s = targets[:, :, list(joint_ids)] * sigma
    rel = s - current[:, :, list(joint_ids)] * sigma
    b, t = targets.shape[:2]
    return torch.cat([rel.reshape(b, t, -1), s.reshape(b, t, -1)], dim=-1).permute(0, 2, 1)


def mask_embedding(codebook: torch.Tensor) -> torch.Tensor:
    """``mask_emb_vq``: the mean of the base-layer codebook (nb_code, code_dim) -> (code_dim,)."""
    return codebook.mean(dim=0)


def estimate_latent(ids: torch.Tensor, codebook: torch.Tensor, known: torch.Tensor) -> torch.Tensor:
    """Base-layer latent of the tokens known so far (Paper A.8): (B, N, code_dim).

    ``ids`` (B, N) any values where not ``known``; known positions take their codebook vector, the
    others (masked and padded positions) the mean code ``mask_emb_vq``.
    """
    safe = torch.where(known, ids, 0).clamp(0, codebook.shape[0] - 1)
    return torch.where(known[..., None], codebook[safe], mask_embedding(codebook))


def _build_control(cfg: ModelConfig) -> nn.Module:
    return MotionControlModel(cfg)


register_part("control", _build_control, requires=("tokenizer", "transformer"))
