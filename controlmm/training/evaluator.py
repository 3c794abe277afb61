"""Training of the text-motion evaluator (``controlmm train evaluator --data DIR --out EVAL_DIR``).

The evaluator is not part of a generative model directory (it must judge any model), so it has its
own directory (:mod:`controlmm.eval.evaluator.model`) and this small loop, which follows the shared
loop's conventions: batches that are a pure function of (seed, step) (the text-to-motion loader of
the transformers: random caption, length rounding, random crop, 196-frame padding), AdamW with
warm-up and step decay, a tqdm progress bar, atomic checkpoints every ``checkpoint_every`` steps and
at every epoch end (``--resume`` continues exactly), validation every epoch, export of the best
weights in float16.

Objective: symmetric InfoNCE between text and motion embeddings of a batch (cosine similarity /
``temperature``), in both directions; pairs whose captions are the same string are not used as
negatives (the corpus repeats captions across clips). The HumanML3D evaluator was trained with a
margin loss on Euclidean distances; InfoNCE converges in far fewer steps, which is what a
15-minute CPU budget needs (see docs/evaluation.md).
"""

from __future__ import annotations

import copy
import json
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import DataLoader

from controlmm.data.datasets import StepBatchSampler, TextMotionDataset
from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError, InputFileError
from controlmm.eval.evaluator.model import (
    MANIFEST,
    WEIGHTS,
    TextMotionEvaluator,
    new_manifest,
    write_evaluator_manifest,
)
from controlmm.eval.evaluator.modules import EVALUATOR_PRESETS, EvaluatorConfig, TextMotionEncoder
from controlmm.eval.evaluator.words import Vocabulary
from controlmm.models.config import StageSchedule
from controlmm.models.model_dir import resolve_device, save_part, write_statistics
from controlmm.training.checkpoint import (
    load_checkpoint,
    rng_state,
    save_checkpoint,
    seed_everything,
    set_rng_state,
)
from controlmm.training.loop import lr_factor
from controlmm.training.stage import VALIDATION_SEED

TEMPERATURE = 0.1
WORD_DROPOUT = 0.1  # training: share of caption words replaced by <unk> (robustness to unseen wording)

SCHEDULES: dict[str, StageSchedule] = {
    # Sized from the measured throughput on 2 shared CPU cores (docs/BENCHMARKS.md, "Quality evaluation").
    "default": StageSchedule(
        iters=1500,
        batch_size=64,
        lr=2e-3,
        weight_decay=1e-4,
        warmup=100,
        milestones=(1150,),
        gamma=0.2,
        checkpoint_every=250,
    ),
    "tiny": StageSchedule(iters=40, batch_size=16, lr=1e-2, warmup=5, checkpoint_every=20),
}


@dataclass
class EvaluatorTrainOptions:
    """What ``controlmm train evaluator`` sets (None = the preset's value)."""

    data: Path
    out: Path
    preset: str = "default"
    iters: int | None = None
    epochs: float | None = None
    batch_size: int | None = None
    lr: float | None = None
    checkpoint_every: int | None = None
    resume: bool = False
    force: bool = False
    seed: int = 0
    device: str | None = None
    threads: int | None = None
    progress: bool = True
    command: str | None = None


def contrastive_loss(
    text: torch.Tensor,
    motion: torch.Tensor,
    caption_ids: torch.Tensor,
    scale: float,
    temperature: float = TEMPERATURE,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Symmetric InfoNCE of (B, D) embeddings on a sphere of radius ``scale``; returns (loss, top-1 accuracy).

    Off-diagonal pairs with the same caption (``caption_ids[i] == caption_ids[j]``) are masked out.
    """
    logits = text @ motion.T / (scale * scale * temperature)
    same = caption_ids[:, None] == caption_ids[None, :]
    same.fill_diagonal_(False)
    logits = logits.masked_fill(same, float("-inf"))
    target = torch.arange(len(text), device=text.device)
    loss = 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))
    acc = (logits.argmax(1) == target).float().mean()
    return loss, acc


def _schedule(opts: EvaluatorTrainOptions, items: int) -> StageSchedule:
    if opts.preset not in SCHEDULES:
        raise ControlMMError(f"unknown evaluator preset '{opts.preset}'; allowed: {', '.join(SCHEDULES)}")
    s = SCHEDULES[opts.preset]
    for name, value in (
        ("batch_size", opts.batch_size),
        ("lr", opts.lr),
        ("checkpoint_every", opts.checkpoint_every),
    ):
        if value is not None:
            s = replace(s, **{name: value})
    if s.batch_size < 2:
        raise ControlMMError(f"batch size must be at least 2 (contrastive pairs); got {s.batch_size}")
    if opts.iters is not None:
        s = replace(s, iters=opts.iters, milestones=tuple(m for m in s.milestones if m < opts.iters))
    elif opts.epochs is not None:
        if not opts.epochs > 0:
            raise ControlMMError(f"--epochs must be positive; got {opts.epochs}")
        s = replace(s, iters=max(1, int(np.ceil(opts.epochs * max(1, items // s.batch_size)))))
    if s.iters < 1 or s.checkpoint_every < 1:
        raise ControlMMError(
            f"iterations and checkpoint interval must be at least 1; got {s.iters}, {s.checkpoint_every}"
        )
    if not s.lr > 0:
        raise ControlMMError(f"learning rate must be positive; got {s.lr}")
    return s


class _Captions:
    """Every caption of the training and validation samples, with its token ids."""

    def __init__(self, samples: list, vocabulary: Vocabulary) -> None:
        texts = sorted({c for s in samples for c in s.captions})
        self.index = {c: i for i, c in enumerate(texts)}
        self.ids, self.lengths = vocabulary.encode(texts)


def retrieval(
    evaluator: TextMotionEvaluator, data: HumanML3D, split: str, repeats: int = 3, seed: int = 0
) -> dict[str, float]:
    """Ground-truth R-precision top-1/2/3 and MM-Dist of a split (evaluation passes of
    :mod:`controlmm.eval.quality`), mean over ``repeats`` passes."""
    from controlmm.eval.quality import EvalSet

    evalset = EvalSet.load(data, split)
    rows = [evalset.draw(seed + r).matching(evaluator) for r in range(repeats)]
    out = {f"r_precision_top{k + 1}": float(np.mean([m.r_precision[k] for m in rows])) for k in range(3)}
    out["mm_dist"] = float(np.mean([m.mm_dist for m in rows]))
    out["pairs"] = rows[0].pairs
    out["repeats"] = repeats
    return out


def train_evaluator(opts: EvaluatorTrainOptions) -> TextMotionEvaluator:
    """Train an evaluator on ``opts.data``'s training split into ``opts.out``; see the module docstring."""
    if opts.preset not in EVALUATOR_PRESETS:
        raise ControlMMError(
            f"unknown evaluator preset '{opts.preset}'; allowed: {', '.join(EVALUATOR_PRESETS)}"
        )
    if opts.threads is not None:
        if opts.threads < 1:
            raise ControlMMError(f"threads must be at least 1; got {opts.threads}")
        torch.set_num_threads(opts.threads)
    if opts.resume and opts.force:
        raise ControlMMError("--resume and --force exclude each other")
    out = Path(opts.out)
    ckpt_path = out / "checkpoints" / f"{WEIGHTS}.pt"
    if not opts.resume and not opts.force and ((out / f"{WEIGHTS}.pt").exists() or ckpt_path.exists()):
        raise ControlMMError(
            f"'{out}' already has evaluator training; pass --resume to continue it "
            "or --force to start it over"
        )
    if opts.resume and not ckpt_path.is_file():
        raise InputFileError(f"nothing to resume: '{ckpt_path}' does not exist")
    device = resolve_device(opts.device)
    data = HumanML3D(opts.data)
    train_samples = data.text_samples("train", progress=opts.progress)
    val_samples = data.text_samples("val", progress=opts.progress)
    seed_everything(opts.seed)

    if opts.resume:
        ckpt = load_checkpoint(ckpt_path)
        vocabulary = Vocabulary(tuple(ckpt["vocabulary"]), ckpt["config"]["max_words"])
        config = EvaluatorConfig.from_dict(ckpt["config"])
    else:
        vocabulary = Vocabulary.build(c for s in train_samples for c in s.captions)
        config = replace(EVALUATOR_PRESETS[opts.preset], vocab_size=len(vocabulary))
    captions = _Captions(train_samples + val_samples, vocabulary)
    dataset = TextMotionDataset(train_samples, data.normalizer, captions.index, unit=4, seed=opts.seed)
    schedule = _schedule(opts, len(dataset))
    steps_per_epoch = len(dataset) // schedule.batch_size
    if steps_per_epoch < 1:
        raise InputFileError(
            f"the training split of '{data.root}' has {len(dataset)} usable items, fewer than "
            f"one batch of {schedule.batch_size}; lower --batch-size"
        )
    model = TextMotionEncoder(config).to(device)
    optimizer = torch.optim.AdamW(
        model.parameters(), lr=schedule.lr, betas=schedule.betas, weight_decay=schedule.weight_decay
    )
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: lr_factor(s, schedule))
    step, history, best, best_state, elapsed, last_val = 0, [], None, None, 0.0, -1
    if opts.resume:
        model.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["scheduler"])
        scheduler.base_lrs = [schedule.lr for _ in optimizer.param_groups]
        step, history, best, best_state = ckpt["step"], ckpt["history"], ckpt["best"], ckpt["best_state"]
        elapsed, last_val = ckpt["elapsed"], ckpt["last_val_step"]
        set_rng_state(ckpt["rng"])
        print(f"resumed evaluator from step {step} ('{ckpt_path}')", flush=True)
    else:
        out.mkdir(parents=True, exist_ok=True)
        write_statistics(out, data.normalizer)
        normalization = {
            "source": str(data.root.resolve()),
            "description": "the training data's Mean.npy/Std.npy (no feat_bias division)",
        }
        write_evaluator_manifest(out, new_manifest(config, vocabulary, normalization))
        if ckpt_path.exists():
            ckpt_path.unlink()

    val_set = TextMotionDataset(
        val_samples, data.normalizer, captions.index, unit=4, seed=VALIDATION_SEED + 1
    )
    val_items = [val_set[(i, 0)] for i in range(len(val_set))]
    ids_all, len_all = captions.ids.to(device), captions.lengths

    def embed(batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        motion, lengths, caption = batch
        ids = ids_all[caption.to(device)]
        if model.training and WORD_DROPOUT > 0:
            ids = ids.masked_fill((torch.rand(ids.shape, device=device) < WORD_DROPOUT) & (ids > 3), 1)
        text = model.encode_text(ids, len_all[caption])
        return text, model.encode_motion(motion.to(device), lengths.to(device)), caption.to(device)

    @torch.no_grad()
    def validate() -> dict[str, float]:
        from controlmm.eval.metrics import matching_metrics

        model.eval()
        t, m, c = [], [], []
        for start in range(0, len(val_items), 128):
            a, b, cap = embed(torch.utils.data.default_collate(val_items[start : start + 128]))
            t.append(a), m.append(b), c.append(cap)
        t, m, c = torch.cat(t), torch.cat(m), torch.cat(c)
        model.train()
        order = torch.from_numpy(np.random.default_rng(VALIDATION_SEED + 2).permutation(len(t))).to(t.device)
        group = min(32, len(t))
        t, m, c = t[order], m[order], c[order]
        match = matching_metrics(t.double().cpu().numpy(), m.double().cpu().numpy(), group=group)
        losses = [
            float(contrastive_loss(t[i : i + group], m[i : i + group], c[i : i + group], config.scale)[0])
            for i in range(0, len(t) - group + 1, group)
        ]
        r = match.r_precision
        return {
            "val_loss": float(np.mean(losses)),
            "val_r1": r[0],
            "val_r2": r[1],
            "val_r3": r[2],
            "val_score": float(np.mean(r)),
            "val_mm_dist": match.mm_dist,
            "step": step,
        }

    def checkpoint() -> None:
        save_checkpoint(
            ckpt_path,
            {
                "stage": "evaluator",
                "step": step,
                "schedule": asdict(schedule),
                "config": config.to_dict(),
                "vocabulary": list(vocabulary.words),
                "model": model.state_dict(),
                "optimizer": optimizer.state_dict(),
                "scheduler": scheduler.state_dict(),
                "rng": rng_state(),
                "history": history,
                "best": best,
                "best_state": best_state,
                "elapsed": elapsed + time.time() - started,
                "last_val_step": last_val,
            },
        )

    from tqdm import tqdm

    print(
        f"evaluator: {len(dataset)} training samples, {len(vocabulary)} words, batch {schedule.batch_size} "
        f"({device}), {steps_per_epoch} steps/epoch, {schedule.iters} iterations "
        f"({schedule.iters / steps_per_epoch:.1f} epochs), checkpoints in {ckpt_path.parent}",
        flush=True,
    )
    started = time.time()
    bar = tqdm(
        total=schedule.iters,
        initial=min(step, schedule.iters),
        desc="train evaluator",
        unit="it",
        disable=not opts.progress,
        dynamic_ncols=True,
        file=sys.stderr,
    )
    model.train()
    running: dict[str, float] = {}
    train_time, train_cpu, train_steps = 0.0, 0.0, 0
    while step < schedule.iters:
        epoch, in_epoch = divmod(step, steps_per_epoch)
        sampler = StepBatchSampler(
            len(dataset),
            schedule.batch_size,
            opts.seed,
            epoch,
            start_step=in_epoch,
            end_step=min(steps_per_epoch, in_epoch + schedule.iters - step),
        )
        loader = DataLoader(
            dataset, batch_sampler=sampler, generator=torch.Generator().manual_seed(opts.seed + epoch)
        )
        tick, cpu_tick = time.time(), time.process_time()
        for batch in loader:
            text, motion, caption = embed(batch)
            loss, acc = contrastive_loss(text, motion, caption, config.scale)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            scheduler.step()
            step += 1
            train_steps += 1
            for k, v in (("loss", float(loss.detach())), ("acc", float(acc))):
                running[k] = 0.9 * running.get(k, v) + 0.1 * v
            bar.update(1)
            if step % 10 == 0 or step == schedule.iters:
                bar.set_postfix(
                    {k: f"{v:.3g}" for k, v in running.items()} | {"lr": f"{scheduler.get_last_lr()[0]:.1e}"}
                )
            if step % schedule.checkpoint_every == 0 and step % steps_per_epoch:
                train_time += time.time() - tick
                train_cpu += time.process_time() - cpu_tick
                checkpoint()
                tick, cpu_tick = time.time(), time.process_time()
        train_time += time.time() - tick
        train_cpu += time.process_time() - cpu_tick
        if step % steps_per_epoch == 0 or step == schedule.iters:
            metrics = validate()
            history.append(metrics)
            last_val = step
            if best is None or metrics["val_score"] >= best["val_score"]:
                best = dict(metrics)
                best_state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
            bar.write(
                f"evaluator step {step} (epoch {step / steps_per_epoch:.2f}): "
                + ", ".join(f"{k}={v:.4g}" for k, v in metrics.items() if k != "step"),
                file=sys.stdout,
            )
            checkpoint()
    bar.close()
    wall = elapsed + time.time() - started
    if last_val != step:  # resumed a finished run: nothing new to validate
        checkpoint()
    export = copy.deepcopy(model).cpu()
    if best_state is not None:
        export.load_state_dict(best_state)
    manifest = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    manifest["part"] = save_part(out, WEIGHTS, export, "float16")
    evaluator = TextMotionEvaluator(export, vocabulary, data.normalizer, manifest, out)
    manifest["training"] = {
        "data": str(Path(opts.data).resolve()),
        "preset": opts.preset,
        "iterations": schedule.iters,
        "epochs": round(schedule.iters / steps_per_epoch, 3),
        "steps_per_epoch": steps_per_epoch,
        "schedule": asdict(schedule),
        "temperature": TEMPERATURE,
        "word_dropout": WORD_DROPOUT,
        "seed": opts.seed,
        "threads": torch.get_num_threads(),
        "device": str(device),
        "wall_time_s": round(wall, 1),
        "throughput_it_s": round(train_steps / train_time, 3)
        if train_time > 0
        else None,  # this session, wall
        "cpu_s_per_it": round(train_cpu / train_steps, 4)
        if train_steps
        else None,  # all threads of this process
        "train_samples": len(dataset),
        "val_samples": len(val_samples),
        "best": best,
        "last": history[-1] if history else None,
        "history": history,
        "command": opts.command,
        "torch": torch.__version__,
    }
    evaluator.manifest = manifest
    manifest["retrieval"] = _final_retrieval(evaluator, data, opts.progress)
    write_evaluator_manifest(out, manifest)
    r = manifest["retrieval"]
    shown = "; ".join(
        f"{split}: R@1/2/3 = " + "/".join(f"{v[f'r_precision_top{k}']:.3f}" for k in (1, 2, 3))
        for split, v in r.items()
    )
    print(
        f"wrote {out / (WEIGHTS + '.pt')} ({manifest['part']['parameters']:,} parameters, "
        f"{manifest['part']['bytes'] / 2**20:.2f} MiB); ground-truth retrieval {shown}",
        flush=True,
    )
    return evaluator


def _final_retrieval(evaluator: TextMotionEvaluator, data: HumanML3D, progress: bool) -> dict[str, Any]:
    out = {}
    for split in ("val", "test"):
        try:
            out[split] = retrieval(evaluator, data, split)
        except ControlMMError as exc:  # a dataset without that split (or too small): recorded, not fatal
            out[split] = {"error": str(exc)}
    return out
