"""Inference-time editing: loss terms on generated joints, logits editing, codebook editing."""

from controlmm.editing.terms import LossTerm, total_loss

__all__ = ["LossTerm", "total_loss"]
