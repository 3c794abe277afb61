"""``STAGES``: the training stages by ``controlmm train <name>`` name (the loop looks them up here)."""

from __future__ import annotations

from typing import Any

from controlmm.training.control import ControlStage
from controlmm.training.evaluator import EvaluatorStage
from controlmm.training.residual import ResidualStage
from controlmm.training.stage import Stage
from controlmm.training.tokenizer import TokenizerStage
from controlmm.training.transformer import TokenTransformerStage, TransformerStage

STAGES: dict[str, type[Stage[Any]]] = {
    "tokenizer": TokenizerStage,
    "transformer": TransformerStage,
    "token_transformer": TokenTransformerStage,
    "residual": ResidualStage,
    "control": ControlStage,
    "evaluator": EvaluatorStage,
}
