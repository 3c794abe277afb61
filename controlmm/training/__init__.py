"""Training of the model parts: one shared loop (:mod:`.loop`), one stage per part.

``STAGES`` maps ``controlmm train <name>`` to its :class:`~controlmm.training.stage.Stage`; later stages
(``control``, ``evaluator``) add themselves here.
"""

from controlmm.training.control import ControlStage
from controlmm.training.loop import TrainOptions, TrainResult, lr_factor, train
from controlmm.training.residual import ResidualStage
from controlmm.training.stage import Stage, StageContext
from controlmm.training.tokenizer import TokenizerStage
from controlmm.training.transformer import TokenTransformerStage, TransformerStage

STAGES: dict[str, type[Stage]] = {
    "tokenizer": TokenizerStage,
    "transformer": TransformerStage,
    "token_transformer": TokenTransformerStage,
    "residual": ResidualStage,
    "control": ControlStage,
}

__all__ = ["STAGES", "Stage", "StageContext", "TrainOptions", "TrainResult", "lr_factor", "train"]
