"""``controlmm train transformer``: train the masked (base-layer) transformer."""

from __future__ import annotations

import argparse

from controlmm.cli.train import EPILOG, add_common_arguments, run_stage

DESCRIPTION = """Train the text-conditioned masked transformer on the base-layer tokens of MODEL_DIR's
tokenizer (cosine masking, BERT corruption, 10% text dropout for classifier-free guidance). Validation each
epoch: masked-token cross-entropy and accuracy."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "transformer",
        help="train the masked (base-layer) transformer",
        description=DESCRIPTION,
        epilog=EPILOG,
    )
    add_common_arguments(p, creates=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_stage("transformer", args)
