"""``controlmm train evaluator``: train the text-motion evaluator used by ``controlmm eval quality``."""

from __future__ import annotations

import argparse

from controlmm.cli.train import run_stage

DESCRIPTION = """Train a text-motion evaluator (a motion encoder and a text encoder into one embedding space,
contrastive InfoNCE) on the training split of a HumanML3D-format directory, for FID, R-precision,
MM-Dist, Diversity and Multimodality (controlmm eval quality). Its text side reads the captions' own
words (a vocabulary of the training captions, learned embeddings, a bidirectional GRU), never the
generator's text encoder. Writes EVAL_DIR/evaluator.json, evaluator.pt (float16), mean.npy, std.npy;
checkpoints go to EVAL_DIR/checkpoints/ (--resume continues a killed run). Validation each epoch:
R-precision of the ground truth on the val split; the best weights are exported. About 13 minutes
on 2 CPU cores for the default corpus.

examples:
  controlmm train evaluator --data CORPUS_DIR --out EVAL_DIR
  controlmm train evaluator --data HumanML3D/ --out EVAL_DIR --epochs 20 --device cuda"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluator",
        help="train the text-motion evaluator (FID, R-precision)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--data", required=True, help="HumanML3D-format data directory")
    p.add_argument("--out", required=True, help="evaluator directory to create")
    p.add_argument("--preset", default="default", help="default or tiny (tests) (default: default)")
    length = p.add_mutually_exclusive_group()
    length.add_argument(
        "--iters", type=int, default=None, help="training iterations (default: the preset's, 1500)"
    )
    length.add_argument(
        "--epochs", type=float, default=None, help="training length in epochs instead of --iters"
    )
    p.add_argument("--batch-size", type=int, default=None, help="batch size (default 64)")
    p.add_argument("--lr", type=float, default=None, help="peak learning rate (default 2e-3)")
    p.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        metavar="N",
        help="write a checkpoint every N iterations (default 250)",
    )
    p.add_argument("--resume", action="store_true", help="continue from EVAL_DIR/checkpoints/evaluator.pt")
    p.add_argument(
        "--force", action="store_true", help="start over, discarding an existing evaluator training"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_stage("evaluator", args)
