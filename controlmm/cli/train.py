"""``controlmm train STAGE ...``: train one part of a model directory.

Stages are modules ``controlmm/cli/train_<name>.py`` listed in :data:`TRAIN_SUBCOMMANDS`; each calls
:func:`add_common_arguments` and :func:`run_stage`. Multi-process training: prefix the command with
``torchrun --nproc_per_node N -m`` (``torchrun --nproc_per_node 2 -m controlmm train tokenizer ...``).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Any

from controlmm.errors import ControlMMError

TRAIN_SUBCOMMANDS: tuple[str, ...] = (
    "tokenizer",
    "transformer",
    "token_transformer",
    "residual",
    "control",
    "evaluator",
)
"""Modules ``controlmm.cli.train_<name>`` that register a training stage, in ``--help`` order."""

HELP = """Train a model directory stage by stage (the same commands for the demo and the paper preset):

  controlmm train tokenizer   --data DIR --preset demo --out MODEL_DIR
  controlmm train transformer --data DIR --out MODEL_DIR
  controlmm train token-transformer --data DIR --out MODEL_DIR   (optional; second text view)
  controlmm train residual    --data DIR --out MODEL_DIR
  controlmm train control     --data DIR --out MODEL_DIR [--joints all|pelvis]
  controlmm train evaluator   --data DIR --out EVAL_DIR   (text-motion evaluator for eval quality)

DIR is a HumanML3D-format directory (the real dataset or the project's corpus). The tokenizer stage
creates MODEL_DIR (model.json, mean.npy, std.npy, tokenizer.pt); later stages add their part
(transformer.pt, residual.pt, control.pt: the motion control model for spatial control).
Checkpoints go to MODEL_DIR/checkpoints/ every few hundred steps; --resume continues a killed run.
Several GPUs (or CPU processes): torchrun --nproc_per_node N -m controlmm train STAGE ..."""

EPILOG = """presets: demo (CPU-sized, MiniLM text; about 2 h (112-118 min) for every stage on 2 cores), paper
(the released MoMask sizes, CLIP ViT-B/32 text, GPU-scale schedules), tiny (tests)."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train the tokenizer, transformers, motion control model or evaluator",
        description=HELP,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    stages = p.add_subparsers(dest="stage", metavar="STAGE", parser_class=type(p))
    for name in TRAIN_SUBCOMMANDS:
        importlib.import_module(f"controlmm.cli.train_{name}").register(stages)
    p.set_defaults(func=lambda args: _no_stage(p))


def _no_stage(parser: argparse.ArgumentParser) -> int:
    from controlmm.models.model_dir import train_command  # heavy: keeps --help fast

    print(
        f"controlmm train: error: choose a stage: {', '.join(map(train_command, TRAIN_SUBCOMMANDS))} "
        "(see 'controlmm train --help')",
        file=sys.stderr,
    )
    return 2


def add_common_arguments(p: argparse.ArgumentParser, creates: bool = False) -> None:
    """Arguments every training stage accepts."""
    p.add_argument("--data", required=True, help="HumanML3D-format data directory")
    p.add_argument("--out", required=True, help="model directory (created by the tokenizer stage)")
    p.add_argument(
        "--preset",
        default=None,
        help="demo, paper or tiny" + (" (default demo)" if creates else " (default: the model directory's)"),
    )
    length = p.add_mutually_exclusive_group()
    length.add_argument("--iters", type=int, default=None, help="training iterations (default: the preset's)")
    length.add_argument(
        "--epochs", type=float, default=None, help="training length in epochs instead of --iters"
    )
    p.add_argument("--batch-size", type=int, default=None, help="global batch size (default: the preset's)")
    p.add_argument("--lr", type=float, default=None, help="peak learning rate (default: the preset's)")
    p.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        metavar="N",
        help="write a checkpoint every N iterations (default: the preset's)",
    )
    p.add_argument("--resume", action="store_true", help="continue from MODEL_DIR/checkpoints/<stage>.pt")
    p.add_argument("--force", action="store_true", help="start this stage over, discarding its checkpoint")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--workers", type=int, default=0, help="data-loading worker processes (default 0)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.add_argument(
        "--precision",
        default="fp32",
        choices=("fp32", "bf16"),
        help="bf16 = bfloat16 autocast of the forward pass: 1.2-1.5x faster on CPUs with "
        "AVX512-BF16 and on GPUs (default fp32)",
    )
    if creates:
        p.add_argument(
            "--text-encoder",
            default=None,
            help="minilm or clip (default: the preset's; fixed for the model directory)",
        )
        p.add_argument(
            "--text-tokens",
            type=int,
            default=None,
            metavar="N",
            help="MiniLM only: condition the masked transformer on the text's token states "
            "(at most N) instead of one sentence vector; 0 = sentence vector (default: "
            "the preset's; fixed for the model directory)",
        )
    p.add_argument(
        "--clip-weights",
        default=None,
        metavar="PATH",
        help="CLIP ViT-B/32 folder saved by transformers (CLIP-conditioned models)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run_stage(name: str, args: argparse.Namespace, stage_options: dict[str, Any] | None = None) -> int:
    """Train stage ``name`` with the parsed command line (options a stage does not offer keep their
    defaults: the evaluator has no --workers, --precision or --clip-weights)."""
    from controlmm.training import TrainOptions, train  # heavy: keeps --help fast

    workers = getattr(args, "workers", 0)
    if workers < 0:
        raise ControlMMError(f"--workers must be >= 0; got {workers}")
    options = TrainOptions(
        data=Path(args.data),
        out=Path(args.out),
        preset=args.preset,
        iters=args.iters,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        checkpoint_every=args.checkpoint_every,
        resume=args.resume,
        force=args.force,
        seed=args.seed,
        device=args.device,
        workers=workers,
        text_encoder=getattr(args, "text_encoder", None),
        clip_weights=getattr(args, "clip_weights", None),
        text_tokens=getattr(args, "text_tokens", None),
        progress=not args.no_progress,
        command="controlmm " + " ".join(sys.argv[1:]),
        precision=getattr(args, "precision", "fp32"),
        threads=args.threads,
        stage_options=dict(stage_options or {}),
    )
    train(name, options)
    return 0
