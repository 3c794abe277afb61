"""Stage ``transformer``: the masked transformer on base-layer tokens of the frozen tokenizer.

Batches come from the text-to-motion loader (random caption, length rounding and crop, 196-frame
padding, trimmed to the batch's longest clip; optionally length-bucketed, ``StageSchedule.bucket``);
tokens are the frozen RVQ-VAE's deterministic base-layer ids of each batch, and text vectors come from
the cached caption embeddings. Validation: masked-token cross-entropy and accuracy on the val split with
fixed crops and masks.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import Any, cast

import torch
from torch import nn

from controlmm.data.datasets import TextMotionDataset
from controlmm.errors import ControlMMError
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.text import embed_captions
from controlmm.training.model_stage import ModelStage, StageContext
from controlmm.training.stage import VALIDATION_SEED


class TextConditionedStage(ModelStage):
    """Shared by the masked and residual transformer stages: samples, captions, tokens."""

    requires: tuple[str, ...] = ("tokenizer",)
    best_metric = "val_loss"

    def __init__(self, ctx: StageContext) -> None:
        super().__init__(ctx)
        data = ctx.data
        self.train_samples = data.text_samples("train", progress=ctx.progress)
        self.val_samples = data.text_samples("val", progress=ctx.progress)
        captions = [c for s in self.train_samples + self.val_samples for c in s.captions]
        base = ctx.trained_parts()
        encoder = base.text_encoder
        emb = embed_captions(
            encoder,
            captions,
            cache_dir=ctx.model_dir / "cache",
            progress=ctx.progress,
            tokens=ctx.config.text_encoder.tokens,
        )
        if emb.vectors.shape[-1] != ctx.config.transformer.text_dim:
            raise ControlMMError(
                f"text encoder '{encoder.name}' gives {emb.vectors.shape[-1]}-d vectors; the "
                f"model expects {ctx.config.transformer.text_dim}-d (wrong CLIP weights?)"
            )
        self.caption_index = emb.index
        self.text_vectors = emb.vectors.to(ctx.device)
        self.tokenizer = base.tokenizer.eval()
        self.unit = ctx.config.tokenizer.downsample

    def train_dataset(self) -> TextMotionDataset:
        return TextMotionDataset(
            self.train_samples, self.ctx.normalizer, self.caption_index, unit=self.unit, seed=self.ctx.seed
        )

    def tokens(self, motion: torch.Tensor) -> torch.Tensor:
        """(B, T, 263) normalised motions (T a multiple of 4) -> (B, T/4, Q) ids of the frozen tokenizer."""
        with torch.no_grad():
            return self.tokenizer.encode(motion)

    def prepare(self, batch: Any) -> tuple:
        motion, lengths, caption = batch
        # Trimmed to the longest clip: the frames beyond it are zero padding in every clip. Only the last
        # few tokens of the longest clip change: they are encoded as the clip alone (the convolutions' own
        # zero padding) instead of next to padded frames, whose activations are not zero.
        motion = motion[:, : int(lengths.max())].to(self.ctx.device, non_blocking=True)
        ids = self.tokens(motion)
        return ids, self.text_vectors[caption.to(self.ctx.device)], (lengths // self.unit).to(self.ctx.device)

    def val_batches(self, batch_size: int = 64) -> Iterator[tuple]:
        """The val split's batches, as :meth:`prepare` gives them (fixed crops and captions)."""
        val = TextMotionDataset(
            self.val_samples,
            self.ctx.normalizer,
            self.caption_index,
            unit=self.unit,
            seed=VALIDATION_SEED + 1,
        )
        for start in range(0, len(val), batch_size):
            items = [val[(i, 0)] for i in range(start, min(len(val), start + batch_size))]
            yield self.prepare(torch.utils.data.default_collate(items))

    def record(self) -> dict[str, Any]:
        return {
            "train_samples": len(self.train_samples),
            "val_samples": len(self.val_samples),
            "captions": len(self.caption_index),
            "text_encoder": self.ctx.config.text_encoder.name,
        }


class MaskedLoss(nn.Module):
    def __init__(self, model: MaskTransformer) -> None:
        super().__init__()
        self.model = model

    def forward(
        self, ids: torch.Tensor, cond: torch.Tensor, lengths: torch.Tensor
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Masked-token cross-entropy on the base-layer ids of (B, N, Q) ``ids``; (loss, metrics)."""
        loss, acc = self.model.masked_loss(ids[..., 0], cond, lengths)
        return loss, {"loss": loss.detach(), "acc": acc.detach()}


class TransformerStage(TextConditionedStage):
    name = "transformer"

    def build_model(self) -> nn.Module:
        return MaskTransformer(self.ctx.config.transformer)

    def loss_module(self, model: nn.Module) -> nn.Module:
        return MaskedLoss(cast(MaskTransformer, model))

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        gen = torch.Generator(self.ctx.device).manual_seed(VALIDATION_SEED + 2)
        total, acc_sum, n = 0.0, 0.0, 0
        transformer = cast(MaskTransformer, model)
        for ids, cond, lengths in self.val_batches():
            loss, acc = transformer.masked_loss(ids[..., 0], cond, lengths, generator=gen)
            total += float(loss) * len(ids)
            acc_sum += float(acc) * len(ids)
            n += len(ids)
        return {"val_loss": total / n, "val_acc": acc_sum / n}


class TokenTransformerStage(TransformerStage):
    """Stage ``token_transformer``: the masked transformer of ``config.token_view`` on MiniLM token states.

    The same objective, data and validation as ``transformer``; only the module (``token_view.transformer``)
    and the text input (at most ``token_view.tokens`` token states per caption) differ. Generation mixes
    the two transformers' log-probabilities (:mod:`controlmm.generate.token_view`).

    Partial warm start: the trained sentence-vector transformer's token and position embeddings, input
    projection, text LayerNorm and projection, output head and relative position bias (when the
    configuration has one) are copied before training; the attention layers start fresh
    (:data:`WARM_START_SKIP`). Layers of their own keep more of the second view's own errors, which is
    what the ensemble gains from (held-out probes: 77.2 % with fresh layers, 76.5 % with every layer
    copied; docs/benchmarks-history.md, "The shippable form: a token-state transformer beside the
    sentence-vector one").
    """

    name = "token_transformer"
    requires = ("tokenizer", "transformer")

    def __init__(self, ctx: StageContext) -> None:
        view = ctx.config.token_view
        if view is None:
            raise ControlMMError(
                f"model directory '{ctx.model_dir}' has no token_view in its configuration "
                "(model directories made with --preset demo or tiny have one)"
            )
        text = replace(ctx.config.text_encoder, tokens=view.tokens)
        super().__init__(
            replace(ctx, config=replace(ctx.config, transformer=view.transformer, text_encoder=text))
        )

    def build_model(self) -> nn.Module:
        model = super().build_model()
        return warm_start(model, self.ctx.trained_parts().transformer, skip=WARM_START_SKIP)


WARM_START_SKIP = ("seqTransEncoder.",)
"""Tensor-name prefixes the token-state stage does not copy: the attention layers."""


def warm_start(model: nn.Module, source: nn.Module, skip: tuple[str, ...] = ()) -> nn.Module:
    """Copy into ``model`` every tensor of ``source`` with the same name and shape, except names starting
    with a prefix in ``skip``; returns ``model``."""
    own, theirs = model.state_dict(), source.state_dict()
    shared = {
        k: v for k, v in theirs.items() if k in own and own[k].shape == v.shape and not k.startswith(skip)
    }
    if not shared:
        raise ControlMMError(
            "warm start: the trained transformer shares no tensor with the token-state transformer"
        )
    model.load_state_dict({**own, **shared})
    return model
