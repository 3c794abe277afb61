"""What a training stage provides to the shared training loop (:mod:`controlmm.training.loop`).

A stage knows its data, its trained module, its loss and its validation; the loop owns devices,
distribution, optimisation, checkpoints, resumption, progress and the model directory. New stages
(the motion control model, the evaluator) subclass :class:`Stage` and register in
:data:`controlmm.training.STAGES`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.utils.data import Dataset

from controlmm.data.humanml3d import HumanML3D
from controlmm.models.config import ModelConfig
from controlmm.models.model_dir import MotionModel
from controlmm.motion.normalization import Normalizer

VALIDATION_SEED = 0
"""Seed of every stage's validation draws (crops, captions, masks), whatever the training seed: the
validation metrics of runs with different ``--seed`` are measured on the same draws and comparable.
(0: seed-0 runs validate exactly as when the draws followed the training seed.)"""


@dataclass
class StageContext:
    """What a stage may use: config, data, the normaliser, the already trained parts, the device."""

    config: ModelConfig
    data: HumanML3D
    normalizer: Normalizer
    model_dir: Path
    device: torch.device
    seed: int
    progress: bool
    base: MotionModel | None  # parts trained by earlier stages (eval mode, frozen), or None
    clip_weights: str | None = None
    is_main: bool = True
    options: dict[str, Any] = field(default_factory=dict)  # stage-specific command-line options
    resume: bool = False


class Stage(ABC):
    """One trainable part. Subclasses set ``name`` and ``requires`` and implement the abstract hooks."""

    name: str = ""
    requires: tuple[str, ...] = ()  # parts that must exist in the model directory before training
    best_metric: str = "val_loss"  # validation metric to minimise; the best weights are exported

    def __init__(self, ctx: StageContext) -> None:
        self.ctx = ctx

    # -- required hooks ---------------------------------------------------------------------------
    @abstractmethod
    def build_model(self) -> nn.Module:
        """The freshly initialised module to train (exported as ``<name>.pt``)."""

    @abstractmethod
    def train_dataset(self) -> Dataset:
        """Dataset indexed by ``(index, epoch)`` keys (see :class:`~controlmm.data.StepBatchSampler`)."""

    @abstractmethod
    def loss_module(self, model: nn.Module) -> nn.Module:
        """A module whose ``forward(*inputs) -> (loss, metrics)`` runs the training objective.

        Its parameters must be the trained model's (it is what ``DistributedDataParallel`` wraps).
        """

    @abstractmethod
    def prepare(self, batch: Any) -> tuple:
        """Collated batch -> the inputs of :meth:`loss_module` (on the device, frozen parts applied)."""

    @abstractmethod
    def validate(self, model: nn.Module) -> dict[str, float]:
        """Validation metrics (must include :attr:`best_metric`); ``model`` is in eval mode."""

    # -- optional hooks ---------------------------------------------------------------------------
    def collate(self, items: list) -> Any:
        return torch.utils.data.default_collate(items)

    def extra_state(self, model: nn.Module) -> dict[str, Any]:
        """State outside ``model.state_dict()`` needed to resume (e.g. EMA statistics)."""
        return {}

    def load_extra_state(self, model: nn.Module, state: dict[str, Any]) -> None:
        pass

    def record(self) -> dict[str, Any]:
        """Extra facts for the training record in model.json (dataset sizes...)."""
        return {}
