"""Stage ``evaluator``: the text-motion evaluator (``controlmm train evaluator --data DIR --out EVAL_DIR``).

The evaluator is not part of a generative model directory (it must judge any model), so it has a
directory of its own (:mod:`controlmm.eval.evaluator.model`): ``evaluator.json`` (configuration, the
training captions' vocabulary, training record, ground-truth retrieval), ``mean.npy``/``std.npy`` (the
training data's, no feat_bias division) and ``evaluator.pt`` (float16). The shared loop trains it like
any stage: batches from the text-to-motion loader of the transformers (random caption, length rounding,
random crop, 196-frame padding), checkpoints and ``--resume``, validation every epoch; the exported
weights are those of the highest ``val_score`` (mean ground-truth R-precision top-1/2/3 on the val split).
The objective is :mod:`controlmm.training.contrastive`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from controlmm.data.datasets import TextMotionDataset
from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError
from controlmm.eval.evaluator.model import (
    MANIFEST,
    WEIGHTS,
    TextMotionEvaluator,
    new_manifest,
    write_evaluator_manifest,
)
from controlmm.eval.evaluator.modules import EVALUATOR_PRESETS, EvaluatorConfig, TextMotionEncoder
from controlmm.eval.evaluator.words import Vocabulary
from controlmm.eval.metrics import matching_metrics
from controlmm.eval.quality import EvalSet
from controlmm.models.config import StageSchedule
from controlmm.models.model_dir import save_part, write_statistics
from controlmm.training.contrastive import TEMPERATURE, WORD_DROPOUT, ContrastiveLoss, contrastive_loss
from controlmm.training.options import TrainOptions
from controlmm.training.schedule import with_overrides
from controlmm.training.stage import VALIDATION_SEED, RunSummary, Stage, StageSetup

SCHEDULES: dict[str, StageSchedule] = {
    # Sized from the measured throughput: the shipped evaluator trained at 1.33 it/s on one thread of a
    # shared 2-core CPU, 19 min in all (the training record in checkpoints/evaluator/evaluator.json).
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


@dataclass(frozen=True)
class EvaluatorContext:
    """What the evaluator stage may use; ``vocabulary`` and ``config`` come from the checkpoint being
    resumed (None: built from the training captions)."""

    data: HumanML3D
    out: Path
    device: torch.device
    seed: int
    progress: bool
    preset: str
    resume: bool
    vocabulary: Vocabulary | None
    config: EvaluatorConfig | None


class EvaluatorStage(Stage[EvaluatorContext]):
    """``controlmm train evaluator``: both encoders of :class:`TextMotionEncoder`, trained together."""

    name = WEIGHTS
    manifest = MANIFEST
    best_metric = "val_score"
    best_mode = "max"

    @classmethod
    def context(cls, setup: StageSetup) -> EvaluatorContext:
        opts = setup.opts
        preset = opts.preset or "default"
        if preset not in EVALUATOR_PRESETS or preset not in SCHEDULES:
            raise ControlMMError(f"unknown evaluator preset '{preset}'; allowed: {', '.join(SCHEDULES)}")
        vocabulary, config = None, None
        if setup.checkpoint is not None:
            # checkpoints written before the evaluator joined the shared loop hold these at the top level
            state = setup.checkpoint.get("extra") or setup.checkpoint
            config = EvaluatorConfig.from_dict(state["config"])
            vocabulary = Vocabulary(tuple(state["vocabulary"]), config.max_words)
        return EvaluatorContext(
            data=setup.data,
            out=Path(opts.out),
            device=setup.dist.device,
            seed=opts.seed,
            progress=opts.progress and setup.dist.is_main,
            preset=preset,
            resume=opts.resume,
            vocabulary=vocabulary,
            config=config,
        )

    def __init__(self, ctx: EvaluatorContext) -> None:
        super().__init__(ctx)
        data = ctx.data
        self.train_samples = data.text_samples("train", progress=ctx.progress)
        self.val_samples = data.text_samples("val", progress=ctx.progress)
        vocabulary, config = ctx.vocabulary, ctx.config
        if vocabulary is None:
            vocabulary = Vocabulary.build(c for s in self.train_samples for c in s.captions)
        if config is None:
            config = replace(EVALUATOR_PRESETS[ctx.preset], vocab_size=len(vocabulary))
        self.vocabulary, self.config = vocabulary, config
        texts = sorted({c for s in self.train_samples + self.val_samples for c in s.captions})
        self.caption_index = {c: i for i, c in enumerate(texts)}
        caption_ids, self.caption_lengths = self.vocabulary.encode(texts)
        self.caption_ids = caption_ids.to(ctx.device)
        val = TextMotionDataset(
            self.val_samples, data.normalizer, self.caption_index, unit=4, seed=VALIDATION_SEED + 1
        )
        self.val_items = [val[(i, 0)] for i in range(len(val))]

    def build_model(self) -> nn.Module:
        return TextMotionEncoder(self.config)

    def train_dataset(self) -> TextMotionDataset:
        return TextMotionDataset(
            self.train_samples, self.ctx.data.normalizer, self.caption_index, unit=4, seed=self.ctx.seed
        )

    def schedule(self, opts: TrainOptions, num_items: int) -> StageSchedule:
        base = SCHEDULES[self.ctx.preset]
        batch_size = base.batch_size if opts.batch_size is None else opts.batch_size
        if batch_size < 2:
            raise ControlMMError(f"batch size must be at least 2 (contrastive pairs); got {batch_size}")
        schedule = with_overrides(base, opts, num_items)
        if opts.iters is not None:  # milestones past the end are dropped from the record
            schedule = replace(schedule, milestones=tuple(m for m in schedule.milestones if m < opts.iters))
        return schedule

    def loss_module(self, model: nn.Module) -> nn.Module:
        return ContrastiveLoss(cast(TextMotionEncoder, model), self.config.scale)

    def prepare(self, batch: Any) -> tuple:
        """(motion, lengths, caption) -> (caption ids, caption lengths (CPU), motion, lengths, caption)."""
        motion, lengths, caption = batch
        device = self.ctx.device
        ids = self.caption_ids[caption.to(device)]
        return ids, self.caption_lengths[caption], motion.to(device), lengths.to(device), caption.to(device)

    @torch.no_grad()
    def validate(self, model: nn.Module) -> dict[str, float]:
        """Ground-truth R-precision (groups of 32, shuffled pairs) and contrastive loss on the val split."""
        encoder = cast(TextMotionEncoder, model)
        texts, motions, captions = [], [], []
        for start in range(0, len(self.val_items), 128):
            batch = torch.utils.data.default_collate(self.val_items[start : start + 128])
            ids, text_lengths, motion, lengths, caption = self.prepare(batch)
            texts.append(encoder.encode_text(ids, text_lengths))
            motions.append(encoder.encode_motion(motion, lengths))
            captions.append(caption)
        t, m, c = torch.cat(texts), torch.cat(motions), torch.cat(captions)
        order = torch.from_numpy(np.random.default_rng(VALIDATION_SEED + 2).permutation(len(t))).to(t.device)
        group = min(32, len(t))
        t, m, c = t[order], m[order], c[order]
        match = matching_metrics(t.double().cpu().numpy(), m.double().cpu().numpy(), group=group)
        losses = [
            float(
                contrastive_loss(t[i : i + group], m[i : i + group], c[i : i + group], self.config.scale)[0]
            )
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
        }

    def extra_state(self, model: nn.Module) -> dict[str, Any]:
        return {"config": self.config.to_dict(), "vocabulary": list(self.vocabulary.words)}

    def create(self) -> None:
        if self.ctx.resume:
            return
        out, data = self.ctx.out, self.ctx.data
        out.mkdir(parents=True, exist_ok=True)
        write_statistics(out, data.normalizer)
        normalization = {
            "source": str(data.root.resolve()),
            "description": "the training data's Mean.npy/Std.npy (no feat_bias division)",
        }
        write_evaluator_manifest(out, new_manifest(self.config, self.vocabulary, normalization))

    def export(self, model: nn.Module, run: RunSummary, opts: TrainOptions) -> None:
        out, data = self.ctx.out, self.ctx.data
        manifest = json.loads((out / MANIFEST).read_text(encoding="utf-8"))  # as create() wrote it
        manifest["part"] = save_part(out, WEIGHTS, model, "float16")
        throughput, cpu_per_step = run.throughput, run.cpu_per_step
        manifest["training"] = {
            "data": str(Path(opts.data).resolve()),
            "preset": self.ctx.preset,
            "iterations": run.schedule.iters,
            "epochs": round(run.schedule.iters / run.steps_per_epoch, 3),
            "steps_per_epoch": run.steps_per_epoch,
            "schedule": asdict(run.schedule),
            "temperature": TEMPERATURE,
            "word_dropout": WORD_DROPOUT,
            "seed": opts.seed,
            "threads": torch.get_num_threads(),
            "device": str(run.device),
            "wall_time_s": round(run.wall_time_s, 1),
            "throughput_it_s": None if throughput is None else round(throughput, 3),  # this session, wall
            "cpu_s_per_it": None if cpu_per_step is None else round(cpu_per_step, 4),  # this process
            "train_samples": len(self.train_samples),
            "val_samples": len(self.val_samples),
            "best": run.best,
            "last": run.last,
            "history": run.history,
            "command": opts.command,
            "torch": torch.__version__,
        }
        evaluator = TextMotionEvaluator(
            cast(TextMotionEncoder, model), self.vocabulary, data.normalizer, manifest, out
        )
        manifest["retrieval"] = final_retrieval(evaluator, data)
        write_evaluator_manifest(out, manifest)
        shown = "; ".join(
            f"{split}: R@1/2/3 = " + "/".join(f"{v[f'r_precision_top{k}']:.3f}" for k in (1, 2, 3))
            for split, v in manifest["retrieval"].items()
            if "error" not in v
        )
        print(
            f"wrote {out / (WEIGHTS + '.pt')} ({manifest['part']['parameters']:,} parameters, "
            f"{manifest['part']['bytes'] / 2**20:.2f} MiB); ground-truth retrieval {shown}",
            flush=True,
        )


def retrieval(
    evaluator: TextMotionEvaluator, data: HumanML3D, split: str, repeats: int = 3, seed: int = 0
) -> dict[str, float]:
    """Ground-truth R-precision top-1/2/3 and MM-Dist of a split (evaluation passes of
    :mod:`controlmm.eval.quality`), mean over ``repeats`` passes."""
    evalset = EvalSet.load(data, split)
    rows = [evalset.draw(seed + r).matching(evaluator) for r in range(repeats)]
    out = {f"r_precision_top{k + 1}": float(np.mean([m.r_precision[k] for m in rows])) for k in range(3)}
    out["mm_dist"] = float(np.mean([m.mm_dist for m in rows]))
    out["pairs"] = rows[0].pairs
    out["repeats"] = repeats
    return out


def final_retrieval(evaluator: TextMotionEvaluator, data: HumanML3D) -> dict[str, dict[str, Any]]:
    """:func:`retrieval` of the val and test splits; a split that is missing or too small is recorded
    as ``{"error": message}``."""
    out: dict[str, dict[str, Any]] = {}
    for split in ("val", "test"):
        try:
            out[split] = dict(retrieval(evaluator, data, split))
        except ControlMMError as exc:
            out[split] = {"error": str(exc)}
    return out
