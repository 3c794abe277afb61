"""Stages that train one part of a motion model directory (``model.json``, :mod:`controlmm.models.model_dir`).

The ``tokenizer`` stage creates the directory: the configuration from ``--preset`` (with
``--text-encoder``/``--text-tokens``), the normalisation statistics of the training data (MoMask's
feat_bias quirk applied). Later stages open it: the configuration from ``model.json``, the parts in
``requires`` loaded and frozen. Each export writes ``<stage>.pt`` and the stage's record under
``training`` in ``model.json``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import torch
from torch import nn

from controlmm.data.humanml3d import HumanML3D
from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import PRESETS, ModelConfig, StageSchedule, preset_config
from controlmm.models.model_dir import (
    MotionModel,
    load_model,
    new_manifest,
    read_manifest,
    read_statistics,
    save_part,
    write_manifest,
    write_statistics,
)
from controlmm.motion.normalization import Normalizer
from controlmm.text import load_text_encoder
from controlmm.text.config import TextEncoderConfig
from controlmm.training.options import TrainOptions
from controlmm.training.schedule import with_overrides
from controlmm.training.stage import RunSummary, Stage, StageSetup

DEFAULT_SCHEDULE = StageSchedule(iters=1000, batch_size=64)
"""The schedule of a stage that neither the model directory nor its preset names."""


@dataclass(kw_only=True)
class StageContext:
    """What a model stage may use: config, data, the normaliser, the already trained parts, the device."""

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
    new_manifest: dict[str, Any] | None = None  # model.json to write: this run creates the directory

    def trained_parts(self) -> MotionModel:
        """``base``: the parts earlier stages trained (a stage that ``requires`` none has no ``base``)."""
        if self.base is None:
            raise ControlMMError(f"model directory '{self.model_dir}' was opened without its trained parts")
        return self.base


class ModelStage(Stage[StageContext]):
    """One part of a model directory; ``requires`` names the parts it is trained on (none: it creates
    the directory)."""

    manifest = "model.json"
    requires: tuple[str, ...] = ()

    @classmethod
    def context(cls, setup: StageSetup) -> StageContext:
        opts, dist = setup.opts, setup.dist
        out = Path(opts.out)
        if setup.has_manifest:
            manifest = read_manifest(out)
            config = ModelConfig.from_dict(manifest["config"])
            check_options_match(config, opts)
            created = None
        elif cls.requires:
            raise InputFileError(
                f"'{out}' has no model.json; train the tokenizer first: "
                f"controlmm train tokenizer --data {opts.data} --out {out}"
            )
        else:
            config = new_config(opts)
            created = new_manifest(config, normalization_record(config, setup.data))
            manifest = created
        missing = [p for p in cls.requires if p not in manifest.get("parts", {})]
        if missing:
            raise InputFileError(
                f"'{out}' has no trained {missing[0]}; train it first: "
                f"controlmm train {missing[0]} --data {opts.data} --out {out}"
            )
        base = None
        if cls.requires:
            base = load_model(out, device=dist.device, parts=cls.requires, clip_weights=opts.clip_weights)
            for module in base.parts.values():
                module.requires_grad_(False)
        normalizer = (
            read_statistics(out)
            if created is None
            else setup.data.normalizer.with_feat_bias(config.feat_bias, config.feat_bias_times)
        )
        return StageContext(
            config=config,
            data=setup.data,
            normalizer=normalizer,
            model_dir=out,
            device=dist.device,
            seed=opts.seed,
            progress=opts.progress and dist.is_main,
            base=base,
            clip_weights=opts.clip_weights,
            is_main=dist.is_main,
            options=dict(opts.stage_options),
            resume=opts.resume,
            new_manifest=created,
        )

    def schedule(self, opts: TrainOptions, num_items: int) -> StageSchedule:
        config = self.ctx.config
        schedule = config.schedules.get(self.name)
        if schedule is None and config.preset in PRESETS:  # a directory made before the stage had one
            schedule = preset_config(config.preset).schedules.get(self.name)
        return with_overrides(schedule or DEFAULT_SCHEDULE, opts, num_items)

    def create(self) -> None:
        if self.ctx.new_manifest is not None:
            self.ctx.model_dir.mkdir(parents=True, exist_ok=True)
            write_statistics(self.ctx.model_dir, self.ctx.normalizer)
            write_manifest(self.ctx.model_dir, self.ctx.new_manifest)

    def record(self) -> dict[str, Any]:
        """Extra facts for the training record in model.json (dataset sizes...)."""
        return {}

    def export(self, model: nn.Module, run: RunSummary, opts: TrainOptions) -> None:
        out, name = self.ctx.model_dir, self.name
        manifest = read_manifest(out)
        config = ModelConfig.from_dict(manifest["config"])
        entry = save_part(out, name, model, config.storage_dtype)
        entry["trained_on"] = {
            dep: manifest["parts"][dep]["sha256"] for dep in self.requires if dep in manifest.get("parts", {})
        }
        manifest["parts"][name] = entry
        manifest["training"][name] = {
            "data": str(Path(opts.data).resolve()),
            "iterations": run.schedule.iters,
            "epochs": round(run.schedule.iters / run.steps_per_epoch, 3),
            "steps_per_epoch": run.steps_per_epoch,
            "schedule": asdict(run.schedule),
            "seed": opts.seed,
            "precision": opts.precision,
            "threads": torch.get_num_threads(),
            "processes": run.processes,
            "device": str(run.device),
            "wall_time_s": round(run.wall_time_s, 1),
            "throughput_it_s": round(run.throughput or 0.0, 3),  # this session (wall clock)
            "cpu_s_per_it": round(run.cpu_per_step or 0.0, 4),  # this process (all threads)
            "exported": "best" if run.exported_best else "last",
            "best_metric": self.best_metric,
            "best": run.best,
            "last": run.last or {},
            "command": opts.command,
            "torch": torch.__version__,
            **self.record(),
        }
        write_manifest(out, manifest)
        best = run.best.get(self.best_metric, float("nan")) if run.best else float("nan")
        print(
            f"wrote {out / entry['file']} ({entry['parameters']:,} parameters, "
            f"{entry['bytes'] / 2**20:.2f} MiB, {self.best_metric}={best:.4g})",
            flush=True,
        )


# -- the configuration of a model directory ---------------------------------------------------------
def check_options_match(config: ModelConfig, opts: TrainOptions) -> None:
    """Refuse ``--preset``, ``--text-encoder`` or ``--text-tokens`` that differ from an existing directory."""
    out = opts.out
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


def new_config(opts: TrainOptions) -> ModelConfig:
    """The configuration of a new model directory: the preset's, with the text-encoder options."""
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
            dim = load_text_encoder(text, device="cpu").dim
            text = replace(text, size=None if dim == text.dim else dim)
        config = config.with_text_encoder(text)
    if opts.text_tokens is not None:
        config = config.with_text_encoder(replace(config.text_encoder, tokens=opts.text_tokens))
    return config


def normalization_record(config: ModelConfig, data: HumanML3D) -> dict[str, Any]:
    """The ``normalization`` entry of a new model.json: where mean.npy/std.npy come from."""
    return {
        "source": str(data.root.resolve()),
        "description": f"HumanML3D Mean.npy/Std.npy of the training data; std of dims 0-3 and 259-262 "
        f"divided by {config.feat_bias:g}**{config.feat_bias_times} (MoMask feat_bias quirk)",
        "feat_bias": config.feat_bias,
        "feat_bias_times": config.feat_bias_times,
    }
