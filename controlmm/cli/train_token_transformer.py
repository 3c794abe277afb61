"""``controlmm train token-transformer``: train the token-state masked transformer (text-view ensemble)."""

from __future__ import annotations

import argparse

from controlmm.cli.train import EPILOG, add_common_arguments, run_stage

DESCRIPTION = """Train the second masked transformer of MODEL_DIR's token_view: the same objective as
'controlmm train transformer', conditioned on MiniLM's token states (one row per word piece) instead of
the pooled sentence vector, starting from part of the trained transformer's weights (embeddings, text
projection and head copied; the attention layers start fresh). Optional: when MODEL_DIR has
token_transformer.pt, text-to-motion decoding averages the two transformers' log-probabilities each
iteration (the two text views fail on different wordings); controlled generation (--control, editing,
plan) keeps the sentence-vector transformer and the motion control model.
Validation each epoch: masked-token cross-entropy and accuracy."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "token-transformer",
        help="train the token-state masked transformer (optional)",
        description=DESCRIPTION,
        epilog=EPILOG,
    )
    add_common_arguments(p, creates=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_stage("token_transformer", args)
