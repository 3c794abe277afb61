"""Stage ``residual``: the residual transformer on all RVQ layers of the frozen tokenizer."""

from __future__ import annotations

from typing import cast

import torch
from torch import nn

from controlmm.models.residual_transformer import ResidualTransformer
from controlmm.training.stage import VALIDATION_SEED
from controlmm.training.transformer import TextConditionedStage


class ResidualLoss(nn.Module):
    def __init__(self, model: ResidualTransformer) -> None:
        super().__init__()
        self.model = model

    def forward(
        self, ids: torch.Tensor, cond: torch.Tensor, lengths: torch.Tensor
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Cross-entropy of the residual layers of (B, N, Q) ``ids``; (loss, metrics)."""
        loss, acc = self.model.residual_loss(ids, cond, lengths)
        return loss, {"loss": loss.detach(), "acc": acc.detach()}


class ResidualStage(TextConditionedStage):
    name = "residual"

    def build_model(self) -> nn.Module:
        return ResidualTransformer(self.ctx.config.residual)

    def loss_module(self, model: nn.Module) -> nn.Module:
        return ResidualLoss(cast(ResidualTransformer, model))

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        gen = torch.Generator(self.ctx.device).manual_seed(VALIDATION_SEED + 3)
        total, acc_sum, n = 0.0, 0.0, 0
        residual = cast(ResidualTransformer, model)
        for ids, cond, lengths in self.val_batches():
            loss, acc = residual.residual_loss(ids, cond, lengths, generator=gen)
            total += float(loss) * len(ids)
            acc_sum += float(acc) * len(ids)
            n += len(ids)
        return {"val_loss": total / n, "val_acc": acc_sum / n}
