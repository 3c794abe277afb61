"""Stage ``residual``: the residual transformer on all RVQ layers of the frozen tokenizer."""

from __future__ import annotations

import torch
from torch import nn

from controlmm.models.residual_transformer import ResidualTransformer
from controlmm.training.stage import VALIDATION_SEED
from controlmm.training.transformer import TextConditionedStage


class ResidualLoss(nn.Module):
    def __init__(self, model: ResidualTransformer) -> None:
        super().__init__()
        self.model = model

    def forward(self, ids, cond, lengths):
        loss, acc = self.model.residual_loss(ids, cond, lengths)
        return loss, {"loss": loss.detach(), "acc": acc.detach()}


class ResidualStage(TextConditionedStage):
    name = "residual"

    def build_model(self) -> nn.Module:
        return ResidualTransformer(self.ctx.config.residual)

    def loss_module(self, model: nn.Module) -> nn.Module:
        return ResidualLoss(model)

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        gen = torch.Generator(self.ctx.device).manual_seed(VALIDATION_SEED + 3)
        total, acc_sum, n = 0.0, 0.0, 0
        for ids, cond, lengths in self.val_batches():
            loss, acc = model.residual_loss(ids, cond, lengths, generator=gen)
            total += float(loss) * len(ids)
            acc_sum += float(acc) * len(ids)
            n += len(ids)
        return {"val_loss": total / n, "val_acc": acc_sum / n}
