"""The training loop shared by every stage.

``train(stage_name, options)``:

1. joins the ``torchrun`` process group when there is one and picks the device;
2. opens (or, for the tokenizer, creates) the model directory: configuration from the preset or from
   ``model.json``, normalisation statistics, the parts trained earlier;
3. builds the stage's module, AdamW and the warm-up + step-decay schedule, restores a checkpoint with
   ``--resume``;
4. steps through batches that are a pure function of (seed, step) (see
   :mod:`controlmm.data.datasets`), with a progress bar, periodic atomic checkpoints, and validation at
   the end of every epoch and of the run;
5. exports the best weights (lowest validation metric) as ``<stage>.pt`` and records the run in
   ``model.json``.
"""

from __future__ import annotations

import copy
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader

from controlmm.data.datasets import StepBatchSampler
from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import PRESETS, ModelConfig, StageSchedule, preset_config
from controlmm.models.model_dir import (
    load_model,
    new_manifest,
    read_manifest,
    read_statistics,
    save_part,
    write_manifest,
    write_statistics,
)
from controlmm.text.config import TextEncoderConfig
from controlmm.training.checkpoint import (
    load_checkpoint,
    rng_state,
    save_checkpoint,
    seed_everything,
    set_rng_state,
)
from controlmm.training.distributed import DistContext, init_distributed, shutdown
from controlmm.training.stage import Stage, StageContext


@dataclass
class TrainOptions:
    """What the ``controlmm train <stage>`` command line sets (None = the preset's value)."""

    data: Path
    out: Path
    preset: str | None = None
    iters: int | None = None
    epochs: float | None = None
    batch_size: int | None = None
    lr: float | None = None
    checkpoint_every: int | None = None
    resume: bool = False
    force: bool = False
    seed: int = 0
    device: str | None = None
    workers: int = 0
    text_encoder: str | None = None
    clip_weights: str | None = None
    text_tokens: int | None = None  # MiniLM token states (TextEncoderConfig.tokens); None = the preset's
    progress: bool = True
    command: str | None = None
    precision: str = (
        "fp32"  # "bf16": bfloat16 autocast of the training forward pass (CPU with AVX512-BF16, GPUs)
    )
    threads: int | None = None  # torch CPU threads (None: torch's default)
    stage_options: dict[str, Any] = field(
        default_factory=dict
    )  # options of one stage (e.g. control's --joints)


@dataclass
class TrainResult:
    model: nn.Module  # the trained module (last weights, unwrapped)
    step: int
    metrics: dict[str, float]  # last validation
    best: dict[str, float]  # validation of the exported weights
    model_dir: Path


def lr_factor(step: int, schedule: StageSchedule) -> float:
    """Linear warm-up over ``warmup`` steps, then x gamma at each milestone."""
    warm = min(1.0, (step + 1) / (schedule.warmup + 1)) if schedule.warmup > 0 else 1.0
    decays = sum(1 for m in schedule.milestones if step >= m)
    return warm * schedule.gamma**decays


# -- model directory ------------------------------------------------------------------------------
def _open_model_dir(
    stage_name: str, opts: TrainOptions, data: HumanML3D, ctx: DistContext, creates: bool, exists: bool
) -> tuple[ModelConfig, dict[str, Any]]:
    out = Path(opts.out)
    if exists:
        manifest = read_manifest(out)
        config = ModelConfig.from_dict(manifest["config"])
        if opts.preset and opts.preset != config.preset:
            raise ControlMMError(
                f"'{out}' holds a '{config.preset}' model; --preset {opts.preset} does not match"
            )
        if opts.text_encoder and opts.text_encoder != config.text_encoder.name:
            raise ControlMMError(
                f"'{out}' uses text encoder '{config.text_encoder.name}'; "
                f"--text-encoder {opts.text_encoder} does not match"
            )
        if opts.text_tokens is not None and opts.text_tokens != config.text_encoder.tokens:
            raise ControlMMError(
                f"'{out}' uses text tokens {config.text_encoder.tokens}; "
                f"--text-tokens {opts.text_tokens} does not match"
            )
        return config, manifest
    if not creates:
        raise InputFileError(
            f"'{out}' has no model.json; train the tokenizer first: "
            f"controlmm train tokenizer --data {opts.data} --out {out}"
        )
    config = preset_config(opts.preset or "demo")
    if opts.text_encoder or opts.clip_weights:
        name = opts.text_encoder or config.text_encoder.name
        weights = opts.clip_weights if name == "clip" else None
        if name == "clip" and weights is None:
            weights = config.text_encoder.weights
        text = TextEncoderConfig(
            name=name,
            weights=weights,
            precision=config.text_encoder.precision,
            tokens=config.text_encoder.tokens if name == "minilm" else 0,
        )
        if name == "clip":  # the vector size comes from the weights (512 for ViT-B/32)
            from controlmm.text import load_text_encoder

            dim = load_text_encoder(text, device="cpu").dim
            text = replace(text, size=None if dim == text.dim else dim)
        config = config.with_text_encoder(text)
    if opts.text_tokens is not None:
        config = config.with_text_encoder(replace(config.text_encoder, tokens=opts.text_tokens))
    normalizer = data.normalizer.with_feat_bias(config.feat_bias, config.feat_bias_times)
    normalization = {
        "source": str(data.root.resolve()),
        "description": f"HumanML3D Mean.npy/Std.npy of the training data; std of dims 0-3 and 259-262 "
        f"divided by {config.feat_bias:g}**{config.feat_bias_times} (MoMask feat_bias quirk)",
        "feat_bias": config.feat_bias,
        "feat_bias_times": config.feat_bias_times,
    }
    manifest = new_manifest(config, normalization)
    if ctx.is_main:
        out.mkdir(parents=True, exist_ok=True)
        write_statistics(out, normalizer)
        write_manifest(out, manifest)
    ctx.barrier()
    return config, manifest


def _schedule(
    config: ModelConfig, stage_name: str, opts: TrainOptions, num_items: int, world: int
) -> StageSchedule:
    """The stage's schedule from the preset, with the command line's overrides."""
    schedule = config.schedules.get(stage_name)
    if schedule is None:  # a model directory created before this stage had a schedule: the preset's
        schedule = (
            preset_config(config.preset).schedules.get(stage_name) if config.preset in PRESETS else None
        )
    schedule = schedule or StageSchedule(iters=1000, batch_size=64)
    for field_name, value in (
        ("batch_size", opts.batch_size),
        ("lr", opts.lr),
        ("checkpoint_every", opts.checkpoint_every),
        ("iters", opts.iters),
    ):
        if value is not None:
            schedule = replace(schedule, **{field_name: value})
    if schedule.batch_size < 1:
        raise ControlMMError(f"batch size must be at least 1; got {schedule.batch_size}")
    if opts.iters is None and opts.epochs is not None:
        if not opts.epochs > 0:
            raise ControlMMError(f"--epochs must be positive; got {opts.epochs}")
        steps_per_epoch = max(1, num_items // schedule.batch_size)
        schedule = replace(schedule, iters=max(1, math.ceil(opts.epochs * steps_per_epoch)))
    for label, value in (("iters", schedule.iters), ("checkpoint interval", schedule.checkpoint_every)):
        if value < 1:
            raise ControlMMError(f"{label} must be at least 1; got {value}")
    if not schedule.lr > 0:
        raise ControlMMError(f"learning rate must be positive; got {schedule.lr}")
    if schedule.batch_size % world:
        raise ControlMMError(f"batch size {schedule.batch_size} is not divisible by the {world} processes")
    return schedule


# -- the loop -------------------------------------------------------------------------------------
def train(stage_name: str, opts: TrainOptions) -> TrainResult:
    """Train one stage into the model directory ``opts.out``; see the module docstring."""
    from controlmm.training import STAGES

    if stage_name not in STAGES:
        raise ControlMMError(f"unknown training stage '{stage_name}'; allowed: {', '.join(STAGES)}")
    stage_cls = STAGES[stage_name]
    if opts.precision not in ("fp32", "bf16"):
        raise ControlMMError(f"unknown precision '{opts.precision}'; allowed: fp32, bf16")
    if opts.threads is not None:
        if opts.threads < 1:
            raise ControlMMError(f"threads must be at least 1; got {opts.threads}")
        torch.set_num_threads(opts.threads)
    ctx = init_distributed(opts.device)
    try:
        return _train(stage_cls, opts, ctx)
    finally:
        shutdown(ctx)


def _train(stage_cls: type[Stage], opts: TrainOptions, ctx: DistContext) -> TrainResult:
    name = stage_cls.name
    out = Path(opts.out)
    ckpt_path = out / "checkpoints" / f"{name}.pt"
    data = HumanML3D(opts.data)
    creates = not stage_cls.requires
    # What exists is decided once, by rank 0, before anyone writes (every process takes the same path).
    found = ctx.broadcast(
        {
            "part": (out / f"{name}.pt").exists(),
            "checkpoint": ckpt_path.is_file(),
            "manifest": (out / "model.json").is_file(),
        }
    )
    if opts.resume and opts.force:
        raise ControlMMError("--resume and --force exclude each other")
    if not opts.resume and not opts.force and (found["part"] or found["checkpoint"]):
        raise ControlMMError(
            f"'{out}' already has {name} training; pass --resume to continue it or --force to start it over"
        )
    if opts.resume and not found["checkpoint"]:
        raise InputFileError(f"nothing to resume: '{ckpt_path}' does not exist")
    config, manifest = _open_model_dir(name, opts, data, ctx, creates, found["manifest"])
    if opts.force and ctx.is_main and ckpt_path.exists():
        ckpt_path.unlink()
    ctx.barrier()
    missing = [p for p in stage_cls.requires if p not in manifest.get("parts", {})]
    if missing:
        raise InputFileError(
            f"'{out}' has no trained {missing[0]}; train it first: "
            f"controlmm train {missing[0]} --data {opts.data} --out {out}"
        )
    base = (
        load_model(out, device=ctx.device, parts=stage_cls.requires, clip_weights=opts.clip_weights)
        if stage_cls.requires
        else None
    )
    if base is not None:
        for module in base.parts.values():
            module.requires_grad_(False)
    seed_everything(opts.seed + ctx.rank)
    sctx = StageContext(
        config=config,
        data=data,
        normalizer=read_statistics(out),
        model_dir=out,
        device=ctx.device,
        seed=opts.seed,
        progress=opts.progress and ctx.is_main,
        base=base,
        clip_weights=opts.clip_weights,
        is_main=ctx.is_main,
        options=dict(opts.stage_options),
        resume=opts.resume,
    )
    stage = stage_cls(sctx)
    model = stage.build_model().to(ctx.device)
    dataset = stage.train_dataset()
    schedule = _schedule(config, name, opts, len(dataset), ctx.world)
    steps_per_epoch = len(dataset) // schedule.batch_size
    if steps_per_epoch < 1:
        raise InputFileError(
            f"the training split of '{data.root}' has {len(dataset)} usable items, fewer "
            f"than one batch of {schedule.batch_size}; lower --batch-size"
        )
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=schedule.lr, betas=schedule.betas, weight_decay=schedule.weight_decay
    )
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: lr_factor(s, schedule))

    step, history, best, best_state, elapsed = 0, [], None, None, 0.0
    last_val_step = -1
    if opts.resume:
        ckpt = load_checkpoint(ckpt_path)
        model.load_state_dict(ckpt["model"])
        stage.load_extra_state(model, ckpt.get("extra", {}))
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["scheduler"])
        scheduler.base_lrs = [schedule.lr for _ in optimizer.param_groups]  # --lr may have changed
        step, history = ckpt["step"], ckpt.get("history", [])
        best, best_state, elapsed = ckpt.get("best"), ckpt.get("best_state"), ckpt.get("elapsed", 0.0)
        last_val_step = ckpt.get("last_val_step", -1)
        states = ckpt.get("rng", [])
        if ctx.rank < len(states) and len(states) == ctx.world:
            set_rng_state(states[ctx.rank])
        else:
            seed_everything(opts.seed + ctx.rank + 7919 * step)
        if ctx.is_main:
            print(f"resumed {name} from step {step} ('{ckpt_path}')", flush=True)

    loss_module = stage.loss_module(model)
    wrapped: nn.Module = loss_module
    if ctx.distributed:
        device_ids = [ctx.device.index] if ctx.device.type == "cuda" else None
        wrapped = DistributedDataParallel(loss_module, device_ids=device_ids)

    def checkpoint() -> None:
        states = ctx.gather(rng_state())
        if ctx.is_main:
            save_checkpoint(
                ckpt_path,
                {
                    "stage": name,
                    "step": step,
                    "schedule": asdict(schedule),
                    "model": model.state_dict(),
                    "extra": stage.extra_state(model),
                    "optimizer": optimizer.state_dict(),
                    "scheduler": scheduler.state_dict(),
                    "rng": states,
                    "history": history,
                    "best": best,
                    "best_state": best_state,
                    "elapsed": elapsed + (time.time() - started),
                    "last_val_step": last_val_step,
                    "world": ctx.world,
                },
            )

    def validate() -> dict[str, float]:
        nonlocal best, best_state, last_val_step
        metrics: dict[str, float] = {}
        if ctx.is_main:
            model.eval()
            metrics = {k: float(v) for k, v in stage.validate(model).items()}
            model.train()
            metrics["step"] = step
            history.append(metrics)
            key = stage.best_metric
            if best is None or metrics[key] <= best[key]:
                best = dict(metrics)
                best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
            shown = ", ".join(f"{k}={v:.4g}" for k, v in metrics.items() if k != "step")
            _log(f"{name} step {step} (epoch {step / steps_per_epoch:.2f}): {shown}", bar)
        last_val_step = step
        ctx.barrier()
        return metrics

    from tqdm import tqdm

    if ctx.is_main:
        print(
            f"{name}: {len(dataset)} training items, batch {schedule.batch_size} on {ctx.world} process(es) "
            f"({ctx.device}), {steps_per_epoch} steps/epoch, {schedule.iters} iterations "
            f"({schedule.iters / steps_per_epoch:.1f} epochs), checkpoints in {ckpt_path.parent}",
            flush=True,
        )
    started = time.time()
    bar = tqdm(
        total=schedule.iters,
        initial=min(step, schedule.iters),
        desc=f"train {name}",
        unit="it",
        disable=not (opts.progress and ctx.is_main),
        dynamic_ncols=True,
        file=sys.stderr,
    )
    model.train()
    train_time, train_cpu, train_steps = 0.0, 0.0, 0
    running: dict[str, float] = {}
    while step < schedule.iters:
        epoch, in_epoch = divmod(step, steps_per_epoch)
        end = min(steps_per_epoch, in_epoch + schedule.iters - step)
        sampler = StepBatchSampler(
            len(dataset),
            schedule.batch_size,
            opts.seed,
            epoch,
            start_step=in_epoch,
            end_step=end,
            rank=ctx.rank,
            world=ctx.world,
            lengths=getattr(dataset, "lengths", None),
            bucket=schedule.bucket,
        )
        # Its own generator: creating a loader must not draw from the global RNG (exact resumption).
        loader = DataLoader(
            dataset,
            batch_sampler=sampler,
            num_workers=opts.workers,
            collate_fn=stage.collate,
            generator=torch.Generator().manual_seed(opts.seed + epoch),
        )
        tick, cpu_tick = time.time(), time.process_time()
        for batch in loader:
            inputs = stage.prepare(batch)
            with torch.autocast(ctx.device.type, dtype=torch.bfloat16, enabled=opts.precision == "bf16"):
                loss, metrics = wrapped(*inputs)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            scheduler.step()
            step += 1
            train_steps += 1
            for k, v in metrics.items():
                running[k] = 0.9 * running.get(k, float(v)) + 0.1 * float(v)
            bar.update(1)
            if bar.n % 10 == 0 or step == schedule.iters:
                shown = {k: f"{v:.3g}" for k, v in running.items()}
                bar.set_postfix(shown | {"lr": f"{scheduler.get_last_lr()[0]:.2e}"})
            if step % schedule.checkpoint_every == 0 and step % steps_per_epoch != 0:
                train_time += time.time() - tick
                train_cpu += time.process_time() - cpu_tick
                checkpoint()
                tick, cpu_tick = time.time(), time.process_time()
        train_time += time.time() - tick
        train_cpu += time.process_time() - cpu_tick
        if step % steps_per_epoch == 0 and step != last_val_step:
            validate()
            checkpoint()
    if last_val_step != step:
        validate()
    checkpoint()
    bar.close()
    total_elapsed = elapsed + (time.time() - started)
    last = history[-1] if history else {}
    if ctx.is_main:
        _export(
            name,
            stage,
            model,
            best_state,
            best,
            last,
            schedule,
            steps_per_epoch,
            opts,
            ctx,
            out,
            total_elapsed,
            train_steps / train_time if train_time > 0 else 0.0,
            train_cpu / train_steps if train_steps else 0.0,
        )
    ctx.barrier()
    return TrainResult(model=model, step=step, metrics=last, best=best or {}, model_dir=out)


def _export(
    name: str,
    stage: Stage,
    model: nn.Module,
    best_state,
    best,
    last,
    schedule: StageSchedule,
    steps_per_epoch: int,
    opts: TrainOptions,
    ctx: DistContext,
    out: Path,
    wall: float,
    throughput: float,
    cpu_per_step: float,
) -> None:
    manifest = read_manifest(out)
    config = ModelConfig.from_dict(manifest["config"])
    export = copy.deepcopy(model).cpu()
    if best_state is not None:
        export.load_state_dict(best_state)
    entry = save_part(out, name, export, config.storage_dtype)
    entry["trained_on"] = {
        dep: manifest["parts"][dep]["sha256"] for dep in stage.requires if dep in manifest.get("parts", {})
    }
    manifest["parts"][name] = entry
    manifest["training"][name] = {
        "data": str(Path(opts.data).resolve()),
        "iterations": schedule.iters,
        "epochs": round(schedule.iters / steps_per_epoch, 3),
        "steps_per_epoch": steps_per_epoch,
        "schedule": asdict(schedule),
        "seed": opts.seed,
        "precision": opts.precision,
        "threads": torch.get_num_threads(),
        "processes": ctx.world,
        "device": str(ctx.device),
        "wall_time_s": round(wall, 1),
        "throughput_it_s": round(throughput, 3),  # this run (wall clock, this session only)
        "cpu_s_per_it": round(cpu_per_step, 4),  # CPU time of this process per iteration (all threads)
        "exported": "best" if best_state is not None else "last",
        "best_metric": stage.best_metric,
        "best": best,
        "last": last,
        "command": opts.command,
        "torch": torch.__version__,
        **stage.record(),
    }
    write_manifest(out, manifest)
    _log(
        f"wrote {out / entry['file']} ({entry['parameters']:,} parameters, {entry['bytes'] / 2**20:.2f} MiB, "
        f"{stage.best_metric}={best.get(stage.best_metric, float('nan')) if best else float('nan'):.4g})",
        None,
    )


def _log(message: str, bar) -> None:
    if bar is not None:
        bar.write(message, file=sys.stdout)
    else:
        print(message, flush=True)
    sys.stdout.flush()
