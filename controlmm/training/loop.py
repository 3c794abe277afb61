"""The training loop shared by every stage (:mod:`controlmm.training.stage`).

``train(stage_name, options)`` joins the ``torchrun`` process group when there is one, picks the device,
then runs four steps:

1. :func:`open_run`: the data, what the output directory holds, the stage (its module, dataset and
   schedule), AdamW and the warm-up + step-decay schedule. Every option is checked before the stage
   writes its directory: a refused option leaves nothing behind;
2. :func:`resume`: with ``--resume``, the checkpoint's module, optimiser, scheduler, RNG states, best
   weights and validation history;
3. :func:`~controlmm.training.steps.run_steps`: batches that are a pure function of (seed, step), a
   progress bar, periodic atomic checkpoints, validation at the end of every epoch and of the run, the
   best weights kept (the stage's ``best_metric``, lowest or highest);
4. :func:`export`: the stage writes the best weights and the training record.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.optim.lr_scheduler import LambdaLR

from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError, InputFileError
from controlmm.training.checkpoint import load_checkpoint, seed_everything, set_rng_state
from controlmm.training.distributed import DistContext, init_distributed, shutdown
from controlmm.training.options import TrainOptions
from controlmm.training.registry import STAGES
from controlmm.training.schedule import check_schedule, lr_factor
from controlmm.training.stage import RunSummary, Stage, StageSetup
from controlmm.training.steps import Run, RunState, run_steps

PRECISIONS = ("fp32", "bf16")


@dataclass
class TrainResult:
    model: nn.Module  # the trained module (last weights, unwrapped)
    step: int
    metrics: dict[str, float]  # last validation
    best: dict[str, float]  # validation of the exported weights
    model_dir: Path


def train(stage_name: str, opts: TrainOptions) -> TrainResult:
    """Train one stage into the directory ``opts.out``; see the module docstring."""
    if stage_name not in STAGES:
        raise ControlMMError(f"unknown training stage '{stage_name}'; allowed: {', '.join(STAGES)}")
    if opts.precision not in PRECISIONS:
        raise ControlMMError(f"unknown precision '{opts.precision}'; allowed: {', '.join(PRECISIONS)}")
    if opts.threads is not None:
        if opts.threads < 1:
            raise ControlMMError(f"threads must be at least 1; got {opts.threads}")
        torch.set_num_threads(opts.threads)
    dist = init_distributed(opts.device)
    try:
        run, checkpoint = open_run(STAGES[stage_name], opts, dist)
        state = resume(run, checkpoint)
        del checkpoint  # its tensors are in the module and optimiser now
        run_steps(run, state)
        return export(run, state)
    finally:
        shutdown(dist)


# -- 1. open --------------------------------------------------------------------------------------
def open_run(
    stage_cls: type[Stage[Any]], opts: TrainOptions, dist: DistContext
) -> tuple[Run, dict[str, Any] | None]:
    """Check the options, build the stage and its optimiser, then let the stage write its directory.

    Returns the run and the checkpoint to resume (None without ``--resume``).
    """
    name, out = stage_cls.name, Path(opts.out)
    checkpoint_path = out / "checkpoints" / f"{name}.pt"
    data = HumanML3D(opts.data)
    # What exists is decided once, by rank 0, before anyone writes (every process takes the same path).
    found = dist.broadcast(
        {
            "part": (out / f"{name}.pt").exists(),
            "checkpoint": checkpoint_path.is_file(),
            "manifest": (out / stage_cls.manifest).is_file(),
        }
    )
    check_resume_options(opts, name, found["part"], found["checkpoint"], checkpoint_path)
    checkpoint = load_checkpoint(checkpoint_path) if opts.resume else None
    ctx = stage_cls.context(StageSetup(opts, data, dist, found["manifest"], checkpoint))
    seed_everything(opts.seed + dist.rank)
    stage = stage_cls(ctx)
    model = stage.build_model().to(dist.device)
    dataset = stage.train_dataset()
    num_items = len(dataset)  # type: ignore[arg-type]  # every stage's dataset is sized
    schedule = stage.schedule(opts, num_items)
    steps_per_epoch = check_schedule(schedule, num_items, dist.world, str(data.root))
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=schedule.lr, betas=schedule.betas, weight_decay=schedule.weight_decay
    )
    scheduler = LambdaLR(optimizer, lambda step: lr_factor(step, schedule))
    # Every option is valid: from here on the directory may be written.
    if dist.is_main:
        stage.create()
        if opts.force and checkpoint_path.exists():
            checkpoint_path.unlink()
    dist.barrier()
    run = Run(
        stage=stage,
        opts=opts,
        dist=dist,
        model=model,
        dataset=dataset,
        num_items=num_items,
        schedule=schedule,
        steps_per_epoch=steps_per_epoch,
        optimizer=optimizer,
        scheduler=scheduler,
        checkpoint_path=checkpoint_path,
    )
    return run, checkpoint


def check_resume_options(
    opts: TrainOptions, name: str, has_part: bool, has_checkpoint: bool, checkpoint_path: Path
) -> None:
    """Refuse to overwrite a stage's training without ``--force``, or to resume what does not exist."""
    if opts.resume and opts.force:
        raise ControlMMError("--resume and --force exclude each other")
    if not opts.resume and not opts.force and (has_part or has_checkpoint):
        raise ControlMMError(
            f"'{opts.out}' already has {name} training; pass --resume to continue it or --force to start "
            "it over"
        )
    if opts.resume and not has_checkpoint:
        raise InputFileError(f"nothing to resume: '{checkpoint_path}' does not exist")


# -- 2. resume ------------------------------------------------------------------------------------
def resume(run: Run, checkpoint: dict[str, Any] | None) -> RunState:
    """The state to start from: a fresh one, or the checkpoint's (module, optimiser, RNG... restored)."""
    if checkpoint is None:
        return RunState()
    run.model.load_state_dict(checkpoint["model"])
    run.stage.load_extra_state(run.model, checkpoint.get("extra", {}))
    run.optimizer.load_state_dict(checkpoint["optimizer"])
    run.scheduler.load_state_dict(checkpoint["scheduler"])
    run.scheduler.base_lrs = [run.schedule.lr for _ in run.optimizer.param_groups]  # --lr may have changed
    state = RunState(
        step=checkpoint["step"],
        history=checkpoint.get("history", []),
        best=checkpoint.get("best"),
        best_state=checkpoint.get("best_state"),
        elapsed=checkpoint.get("elapsed", 0.0),
        last_val_step=checkpoint.get("last_val_step", -1),
    )
    states = checkpoint.get("rng", [])
    if isinstance(states, dict):  # one process's state: evaluator checkpoints before the shared loop
        states = [states]
    if run.dist.rank < len(states) and len(states) == run.dist.world:
        set_rng_state(states[run.dist.rank])
    else:
        seed_everything(run.opts.seed + run.dist.rank + 7919 * state.step)
    if run.dist.is_main:
        print(f"resumed {run.stage.name} from step {state.step} ('{run.checkpoint_path}')", flush=True)
    return state


# -- 4. export ------------------------------------------------------------------------------------
def export(run: Run, state: RunState) -> TrainResult:
    """The stage writes the best weights (the last ones when none was validated) and its record."""
    if run.dist.is_main:
        model = copy.deepcopy(run.model).cpu()
        if state.best_state is not None:
            model.load_state_dict(state.best_state)
        summary = RunSummary(
            schedule=run.schedule,
            steps_per_epoch=run.steps_per_epoch,
            best=state.best,
            history=state.history,
            exported_best=state.best_state is not None,
            processes=run.dist.world,
            device=run.dist.device,
            wall_time_s=state.elapsed + (time.time() - state.started),
            train_steps=state.train_steps,
            train_time_s=state.train_time,
            train_cpu_s=state.train_cpu,
        )
        run.stage.export(model, summary, run.opts)
    run.dist.barrier()
    last = state.history[-1] if state.history else {}
    return TrainResult(
        model=run.model, step=state.step, metrics=last, best=state.best or {}, model_dir=Path(run.opts.out)
    )
