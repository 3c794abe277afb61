"""What the ``controlmm train <stage>`` command line sets: :class:`TrainOptions`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class TrainOptions:
    """Options of one training run (None = the preset's value).

    ``precision``: ``fp32`` or ``bf16`` (bfloat16 autocast of the training forward pass; CPUs with
    AVX512-BF16 and GPUs). ``threads``: torch CPU threads (None: torch's default). ``text_tokens``:
    MiniLM token states (``TextEncoderConfig.tokens``; None: the preset's). ``stage_options``: options of
    one stage (e.g. control's ``--joints``).
    """

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
    text_tokens: int | None = None
    progress: bool = True
    command: str | None = None
    precision: str = "fp32"
    threads: int | None = None
    stage_options: dict[str, Any] = field(default_factory=dict)
