"""Training of the model parts and of the evaluator: one shared loop (:mod:`.loop`), one stage per part.

``STAGES`` (:mod:`.registry`) maps ``controlmm train <name>`` to its :class:`~controlmm.training.stage.Stage`.
"""

from controlmm.training.loop import TrainResult, train
from controlmm.training.model_stage import ModelStage, StageContext
from controlmm.training.options import TrainOptions
from controlmm.training.registry import STAGES
from controlmm.training.schedule import lr_factor
from controlmm.training.stage import Stage

__all__ = [
    "STAGES",
    "ModelStage",
    "Stage",
    "StageContext",
    "TrainOptions",
    "TrainResult",
    "lr_factor",
    "train",
]
