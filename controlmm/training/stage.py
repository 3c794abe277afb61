"""What a training stage provides to the shared training loop (:mod:`controlmm.training.loop`).

A stage knows its data, its trained module, its loss, its validation and its output directory; the loop
owns devices, distribution, optimisation, checkpoints, resumption, progress and the order of the run:

1. ``context(setup)`` (class method) reads what the stage needs from the output directory, writing
   nothing; the loop seeds the generators and builds the stage from it;
2. ``build_model``, ``train_dataset`` and ``schedule`` refuse bad options (every check passes before
   anything is written); then ``create`` writes the directory (main process only);
3. steps: ``prepare`` + ``loss_module``; ``validate`` at every epoch end and at the end of the run, the
   best weights by ``best_metric`` (lowest or highest, ``best_mode``) kept;
4. ``export`` writes the best weights and the training record.

Two families: :class:`~controlmm.training.model_stage.ModelStage` (one part of a motion model
directory) and :class:`~controlmm.training.evaluator.EvaluatorStage` (the text-motion evaluator, in a
directory of its own). Stages register in :data:`controlmm.training.registry.STAGES`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

import torch
from torch import nn
from torch.utils.data import Dataset

from controlmm.data.humanml3d import HumanML3D
from controlmm.models.config import StageSchedule
from controlmm.training.distributed import DistContext
from controlmm.training.options import TrainOptions

VALIDATION_SEED = 0
"""Seed of every stage's validation draws (crops, captions, masks), whatever the training seed: the
validation metrics of runs with different ``--seed`` are measured on the same draws and comparable.
(0: seed-0 runs validate exactly as when the draws followed the training seed.)"""

ContextT = TypeVar("ContextT")


@dataclass(frozen=True)
class StageSetup:
    """What the loop knows before a stage exists (the argument of :meth:`Stage.context`)."""

    opts: TrainOptions
    data: HumanML3D
    dist: DistContext
    has_manifest: bool  # the output directory holds the stage's manifest (decided by rank 0)
    checkpoint: dict[str, Any] | None  # the checkpoint being resumed (``--resume``), else None


@dataclass(frozen=True)
class RunSummary:
    """What the loop hands to :meth:`Stage.export`: schedule, validation results and timings of a run."""

    schedule: StageSchedule
    steps_per_epoch: int
    best: dict[str, float] | None  # validation of the exported weights (None: never validated)
    history: list[dict[str, float]]  # every validation, in step order
    exported_best: bool  # False: the last weights are exported (no best was recorded)
    processes: int
    device: torch.device
    wall_time_s: float  # every session of the run (resumed ones included)
    train_steps: int  # this session only, as the two timings below
    train_time_s: float  # wall clock of the training steps
    train_cpu_s: float  # CPU time of this process in the training steps (all threads)

    @property
    def last(self) -> dict[str, float] | None:
        """The last validation, or None."""
        return self.history[-1] if self.history else None

    @property
    def throughput(self) -> float | None:
        """Training iterations per second of this session (None: no step ran)."""
        return self.train_steps / self.train_time_s if self.train_time_s > 0 else None

    @property
    def cpu_per_step(self) -> float | None:
        """CPU seconds per training iteration of this session (None: no step ran)."""
        return self.train_cpu_s / self.train_steps if self.train_steps else None


class Stage(ABC, Generic[ContextT]):
    """One trainable module. Subclasses set ``name`` and ``manifest`` and implement the abstract hooks."""

    name: str = ""
    manifest: str = ""  # the file that describes the output directory (model.json, evaluator.json)
    best_metric: str = "val_loss"  # validation metric that selects the exported weights
    best_mode: Literal["min", "max"] = "min"  # keep its lowest ("min") or its highest ("max") value

    def __init__(self, ctx: ContextT) -> None:
        self.ctx = ctx

    # -- required hooks ---------------------------------------------------------------------------
    @classmethod
    @abstractmethod
    def context(cls, setup: StageSetup) -> ContextT:
        """What the constructor receives, read from ``setup.opts.out`` (nothing written)."""

    @abstractmethod
    def build_model(self) -> nn.Module:
        """The freshly initialised module to train (exported as ``<name>.pt``)."""

    @abstractmethod
    def train_dataset(self) -> Dataset:
        """Dataset indexed by ``(index, epoch)`` keys (see :class:`~controlmm.data.StepBatchSampler`)."""

    @abstractmethod
    def schedule(self, opts: TrainOptions, num_items: int) -> StageSchedule:
        """The run's schedule: the stage's base schedule with the command line's overrides
        (:func:`~controlmm.training.schedule.with_overrides`); ``num_items`` training items."""

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

    @abstractmethod
    def create(self) -> None:
        """Write the output directory before the first step (main process; every option is valid)."""

    @abstractmethod
    def export(self, model: nn.Module, run: RunSummary, opts: TrainOptions) -> None:
        """Write the trained ``model`` (CPU, the weights to ship) and the training record (main process)."""

    # -- optional hooks ---------------------------------------------------------------------------
    def collate(self, items: list) -> Any:
        return torch.utils.data.default_collate(items)

    def extra_state(self, model: nn.Module) -> dict[str, Any]:
        """State outside ``model.state_dict()`` needed to resume (e.g. EMA statistics)."""
        return {}

    def load_extra_state(self, model: nn.Module, state: dict[str, Any]) -> None:
        pass

    @classmethod
    def is_better(cls, metrics: dict[str, float], best: dict[str, float] | None) -> bool:
        """Whether ``metrics`` replace ``best`` (ties too: the later weights win)."""
        if best is None:
            return True
        value, kept = metrics[cls.best_metric], best[cls.best_metric]
        return value >= kept if cls.best_mode == "max" else value <= kept
