"""Step 3 of the shared loop (:mod:`controlmm.training.loop`): the training steps of an opened run.

Batches are a pure function of (seed, step) (see :mod:`controlmm.data.datasets`); a progress bar shows
the smoothed training metrics; an atomic checkpoint is written every ``checkpoint_every`` steps and at
every epoch end, after the validation; the last validation and checkpoint come at the end of the run.
The weights of the best validation (the stage's ``best_metric``, lowest or highest) are kept for export.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from torch.optim.lr_scheduler import LambdaLR
from torch.utils.data import DataLoader, Dataset
from tqdm import tqdm

from controlmm.data.datasets import StepBatchSampler
from controlmm.models.config import StageSchedule
from controlmm.training.checkpoint import rng_state, save_checkpoint
from controlmm.training.distributed import DistContext
from controlmm.training.options import TrainOptions
from controlmm.training.stage import Stage


@dataclass
class Run:
    """An opened run (step 1): everything fixed for its whole length."""

    stage: Stage[Any]
    opts: TrainOptions
    dist: DistContext
    model: nn.Module
    dataset: Dataset
    num_items: int
    schedule: StageSchedule
    steps_per_epoch: int
    optimizer: torch.optim.Optimizer
    scheduler: LambdaLR
    checkpoint_path: Path


@dataclass
class RunState:
    """What changes as a run goes (saved in every checkpoint, except this session's timings)."""

    step: int = 0
    history: list[dict[str, float]] = field(default_factory=list)
    best: dict[str, float] | None = None
    best_state: dict[str, torch.Tensor] | None = None
    elapsed: float = 0.0  # wall seconds of the earlier sessions
    last_val_step: int = -1
    started: float = field(default_factory=time.time)  # this session
    train_steps: int = 0  # this session: steps, their wall clock and CPU seconds
    train_time: float = 0.0
    train_cpu: float = 0.0
    running: dict[str, float] = field(default_factory=dict)  # smoothed training metrics (progress bar)


def run_steps(run: Run, state: RunState) -> None:
    """Train up to ``schedule.iters`` steps: validation and a checkpoint at every epoch end, a checkpoint
    every ``checkpoint_every`` steps, and a last validation and checkpoint at the end."""
    loss_module = run.stage.loss_module(run.model)
    wrapped: nn.Module = loss_module
    if run.dist.distributed:
        device = run.dist.device
        wrapped = DistributedDataParallel(
            loss_module, device_ids=[device.index] if device.type == "cuda" else None
        )
    if run.dist.is_main:
        s = run.schedule
        print(
            f"{run.stage.name}: {run.num_items} training items, batch {s.batch_size} on {run.dist.world} "
            f"process(es) ({run.dist.device}), {run.steps_per_epoch} steps/epoch, {s.iters} iterations "
            f"({s.iters / run.steps_per_epoch:.1f} epochs), checkpoints in {run.checkpoint_path.parent}",
            flush=True,
        )
    state.started = time.time()
    bar = tqdm(
        total=run.schedule.iters,
        initial=min(state.step, run.schedule.iters),
        desc=f"train {run.stage.name}",
        unit="it",
        disable=not (run.opts.progress and run.dist.is_main),
        dynamic_ncols=True,
        file=sys.stderr,
    )
    run.model.train()
    while state.step < run.schedule.iters:
        train_epoch(run, state, wrapped, bar)
        if state.step % run.steps_per_epoch == 0 and state.step != state.last_val_step:
            validate(run, state, bar)
            write_checkpoint(run, state)
    if state.last_val_step != state.step:
        validate(run, state, bar)
    write_checkpoint(run, state)
    bar.close()


def train_epoch(run: Run, state: RunState, wrapped: nn.Module, bar: tqdm) -> None:
    """The steps from ``state.step`` to the end of its epoch (or of the run)."""
    opts, schedule = run.opts, run.schedule
    epoch, in_epoch = divmod(state.step, run.steps_per_epoch)
    sampler = StepBatchSampler(
        run.num_items,
        schedule.batch_size,
        opts.seed,
        epoch,
        start_step=in_epoch,
        end_step=min(run.steps_per_epoch, in_epoch + schedule.iters - state.step),
        rank=run.dist.rank,
        world=run.dist.world,
        lengths=getattr(run.dataset, "lengths", None),
        bucket=schedule.bucket,
    )
    # Its own generator: creating a loader must not draw from the global RNG (exact resumption).
    loader = DataLoader(
        run.dataset,
        batch_sampler=sampler,
        num_workers=opts.workers,
        collate_fn=run.stage.collate,
        generator=torch.Generator().manual_seed(opts.seed + epoch),
    )
    tick, cpu_tick = time.time(), time.process_time()
    for batch in loader:
        inputs = run.stage.prepare(batch)
        with torch.autocast(run.dist.device.type, dtype=torch.bfloat16, enabled=opts.precision == "bf16"):
            loss, metrics = wrapped(*inputs)
        run.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        run.optimizer.step()
        run.scheduler.step()
        state.step += 1
        state.train_steps += 1
        for k, v in metrics.items():
            state.running[k] = 0.9 * state.running.get(k, float(v)) + 0.1 * float(v)
        bar.update(1)
        if bar.n % 10 == 0 or state.step == schedule.iters:
            shown = {k: f"{v:.3g}" for k, v in state.running.items()}
            bar.set_postfix(shown | {"lr": f"{run.scheduler.get_last_lr()[0]:.2e}"})
        if state.step % schedule.checkpoint_every == 0 and state.step % run.steps_per_epoch != 0:
            state.train_time += time.time() - tick
            state.train_cpu += time.process_time() - cpu_tick
            write_checkpoint(run, state)
            tick, cpu_tick = time.time(), time.process_time()
    state.train_time += time.time() - tick
    state.train_cpu += time.process_time() - cpu_tick


def validate(run: Run, state: RunState, bar: tqdm) -> None:
    """Validate on the main process; keep the weights when the stage's best metric improves."""
    if run.dist.is_main:
        model, stage = run.model, run.stage
        model.eval()
        metrics = {k: float(v) for k, v in stage.validate(model).items()}
        model.train()
        metrics["step"] = state.step
        state.history.append(metrics)
        if stage.is_better(metrics, state.best):
            state.best = dict(metrics)
            state.best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
        shown = ", ".join(f"{k}={v:.4g}" for k, v in metrics.items() if k != "step")
        bar.write(
            f"{stage.name} step {state.step} (epoch {state.step / run.steps_per_epoch:.2f}): {shown}",
            file=sys.stdout,
        )
        sys.stdout.flush()
    state.last_val_step = state.step
    run.dist.barrier()


def write_checkpoint(run: Run, state: RunState) -> None:
    """Write the checkpoint atomically (every process's RNG state, the main process writes)."""
    states = run.dist.gather(rng_state())
    if not run.dist.is_main:
        return
    save_checkpoint(
        run.checkpoint_path,
        {
            "stage": run.stage.name,
            "step": state.step,
            "schedule": asdict(run.schedule),
            "model": run.model.state_dict(),
            "extra": run.stage.extra_state(run.model),
            "optimizer": run.optimizer.state_dict(),
            "scheduler": run.scheduler.state_dict(),
            "rng": states,
            "history": state.history,
            "best": state.best,
            "best_state": state.best_state,
            "elapsed": state.elapsed + (time.time() - state.started),
            "last_val_step": state.last_val_step,
            "world": run.dist.world,
        },
    )
