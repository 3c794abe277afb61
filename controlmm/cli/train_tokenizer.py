"""``controlmm train tokenizer``: train the RVQ-VAE tokenizer (creates the model directory)."""

from __future__ import annotations

import argparse

from controlmm.cli.train import EPILOG, add_common_arguments, run_stage

DESCRIPTION = """Train the RVQ-VAE motion tokenizer (6 residual codebooks) on random 64-frame windows. Creates
MODEL_DIR with model.json, mean.npy/std.npy (the data's Mean/Std with MoMask's feat_bias quirk) and
tokenizer.pt. Validation each epoch: reconstruction loss, MPJPE (mm), code usage."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tokenizer",
        help="train the RVQ-VAE tokenizer (creates the model directory)",
        description=DESCRIPTION,
        epilog=EPILOG,
    )
    add_common_arguments(p, creates=True)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_stage("tokenizer", args)
