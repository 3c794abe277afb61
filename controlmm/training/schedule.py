"""The optimisation schedule of a run: learning-rate factor, command-line overrides, checks.

A stage names its base :class:`~controlmm.models.config.StageSchedule` (from the model's preset, or the
evaluator's presets); :func:`with_overrides` applies ``--batch-size``, ``--lr``, ``--checkpoint-every``
and ``--iters``/``--epochs``; :func:`check_schedule` refuses what cannot run, before anything is written.
"""

from __future__ import annotations

import math
from dataclasses import replace

from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import StageSchedule
from controlmm.training.options import TrainOptions


def lr_factor(step: int, schedule: StageSchedule) -> float:
    """Linear warm-up over ``warmup`` steps, then x gamma at each milestone."""
    warm = min(1.0, (step + 1) / (schedule.warmup + 1)) if schedule.warmup > 0 else 1.0
    decays = sum(1 for m in schedule.milestones if step >= m)
    return warm * schedule.gamma**decays


def with_overrides(schedule: StageSchedule, opts: TrainOptions, num_items: int) -> StageSchedule:
    """``schedule`` with the command line's values; ``--epochs`` counts epochs of ``num_items`` items."""
    if opts.batch_size is not None:
        schedule = replace(schedule, batch_size=opts.batch_size)
    if opts.lr is not None:
        schedule = replace(schedule, lr=opts.lr)
    if opts.checkpoint_every is not None:
        schedule = replace(schedule, checkpoint_every=opts.checkpoint_every)
    if opts.iters is not None:
        schedule = replace(schedule, iters=opts.iters)
    if schedule.batch_size < 1:
        raise ControlMMError(f"batch size must be at least 1; got {schedule.batch_size}")
    if opts.iters is None and opts.epochs is not None:
        if not opts.epochs > 0:
            raise ControlMMError(f"--epochs must be positive; got {opts.epochs}")
        steps_per_epoch = max(1, num_items // schedule.batch_size)
        schedule = replace(schedule, iters=max(1, math.ceil(opts.epochs * steps_per_epoch)))
    return schedule


def check_schedule(schedule: StageSchedule, num_items: int, world: int, data: str) -> int:
    """Refuse a schedule that cannot run on ``num_items`` training items over ``world`` processes;
    returns the steps per epoch. ``data`` names the training data in the message."""
    for label, value in (("iters", schedule.iters), ("checkpoint interval", schedule.checkpoint_every)):
        if value < 1:
            raise ControlMMError(f"{label} must be at least 1; got {value}")
    if not schedule.lr > 0:
        raise ControlMMError(f"learning rate must be positive; got {schedule.lr}")
    if schedule.batch_size % world:
        raise ControlMMError(f"batch size {schedule.batch_size} is not divisible by the {world} processes")
    if num_items < 1:
        raise InputFileError(
            f"'{data}' has no usable training items (empty training split, or clips too short)"
        )
    if schedule.batch_size > num_items:
        raise ControlMMError(
            f"batch size {schedule.batch_size} is more than the {num_items} usable training items of "
            f"'{data}'; pass --batch-size {num_items} or less"
        )
    return num_items // schedule.batch_size
