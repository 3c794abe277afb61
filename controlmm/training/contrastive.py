"""The evaluator's objective: symmetric InfoNCE between text and motion embeddings of a batch.

Cosine similarity / ``temperature``, in both directions; pairs whose captions are the same string are
not used as negatives (the corpus repeats captions across clips). During training a share of the
caption words (``WORD_DROPOUT``) is replaced by ``<unk>`` (robustness to unseen wording). The HumanML3D
evaluator was trained with a margin loss on Euclidean distances; InfoNCE converges in far fewer steps,
which is what a 15-minute CPU budget needs (see docs/evaluation.md).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from controlmm.eval.evaluator.modules import TextMotionEncoder

TEMPERATURE = 0.1
WORD_DROPOUT = 0.1  # training: share of caption words replaced by <unk> (robustness to unseen wording)
UNKNOWN_ID = 1  # <unk> in every evaluator vocabulary; ids 0-3 are the special words, never dropped


def contrastive_loss(
    text: torch.Tensor,
    motion: torch.Tensor,
    caption_ids: torch.Tensor,
    scale: float,
    temperature: float = TEMPERATURE,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Symmetric InfoNCE of (B, D) embeddings on a sphere of radius ``scale``; returns (loss, top-1 accuracy).

    Off-diagonal pairs with the same caption (``caption_ids[i] == caption_ids[j]``) are masked out.
    """
    logits = text @ motion.T / (scale * scale * temperature)
    same = caption_ids[:, None] == caption_ids[None, :]
    same.fill_diagonal_(False)
    logits = logits.masked_fill(same, float("-inf"))
    target = torch.arange(len(text), device=text.device)
    loss = 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))
    acc = (logits.argmax(1) == target).float().mean()
    return loss, acc


class ContrastiveLoss(nn.Module):
    """Training objective of the evaluator stage: word dropout, both encoders, :func:`contrastive_loss`."""

    def __init__(self, model: TextMotionEncoder, scale: float) -> None:
        super().__init__()
        self.model = model
        self.scale = scale

    def forward(
        self,
        ids: torch.Tensor,
        text_lengths: torch.Tensor,
        motion: torch.Tensor,
        lengths: torch.Tensor,
        caption: torch.Tensor,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Caption token ids (B, L) with lengths (B,) (CPU), normalised motions (B, T, 263) with lengths
        (B,) frames, caption indices (B,) -> (loss, {"loss", "acc"})."""
        if self.model.training and WORD_DROPOUT > 0:
            drop = (torch.rand(ids.shape, device=ids.device) < WORD_DROPOUT) & (ids > 3)
            ids = ids.masked_fill(drop, UNKNOWN_ID)
        text = self.model.encode_text(ids, text_lengths)
        motion_emb = self.model.encode_motion(motion, lengths)
        loss, acc = contrastive_loss(text, motion_emb, caption, self.scale)
        return loss, {"loss": loss.detach(), "acc": acc}
