"""The training loop shared by every stage (:mod:`controlmm.training.stage`).

``train(stage_name, options)`` joins the ``torchrun`` process group when there is one, picks the device,
then runs four steps:

1. :func:`open_run`: the data, what the output directory holds, the stage (its module, dataset and
   schedule), AdamW and the warm-up + step-decay schedule. Every option is checked before the stage
   writes its directory: a refused option leaves nothing behind;
2. :func:`resume`: with ``--resume``, the checkpoint's module, optimiser, scheduler, RNG states, best
   weights and validation history;
3. :func:`run_steps`: batches that are a pure function of (seed, step) (see
   :mod:`controlmm.data.datasets`), a progress bar, periodic atomic checkpoints, validation at the end of
   every epoch and of the run, the best weights kept (the stage's ``best_metric``, lowest or highest);
4. :func:`export`: the stage writes the best weights and the training record.
"""

from __future__ import annotations

import copy
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
from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import StageSchedule
from controlmm.training.checkpoint import (
    load_checkpoint,
    rng_state,
    save_checkpoint,
    seed_everything,
    set_rng_state,
)
from controlmm.training.distributed import DistContext, init_distributed, shutdown
from controlmm.training.options import TrainOptions
from controlmm.training.registry import STAGES
from controlmm.training.schedule import check_schedule, lr_factor
from controlmm.training.stage import RunSummary, Stage, StageSetup

PRECISIONS = ("fp32", "bf16")


@dataclass
class TrainResult:
    model: nn.Module  # the trained module (last weights, unwrapped)
    step: int
    metrics: dict[str, float]  # last validation
    best: dict[str, float]  # validation of the exported weights
    model_dir: Path


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
        del checkpoint
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
    if opts.resume and opts.force:
        raise ControlMMError("--resume and --force exclude each other")
    if not opts.resume and not opts.force and (found["part"] or found["checkpoint"]):
        raise ControlMMError(
            f"'{out}' already has {name} training; pass --resume to continue it or --force to start it over"
        )
    if opts.resume and not found["checkpoint"]:
        raise InputFileError(f"nothing to resume: '{checkpoint_path}' does not exist")
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


# -- 3. run ---------------------------------------------------------------------------------------
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
            save(run, state)
    if state.last_val_step != state.step:
        validate(run, state, bar)
    save(run, state)
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
            save(run, state)
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


def save(run: Run, state: RunState) -> None:
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
