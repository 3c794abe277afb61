"""``controlmm train residual``: train the residual transformer."""

from __future__ import annotations

import argparse

from controlmm.cli.train import EPILOG, add_common_arguments, run_stage

DESCRIPTION = """Train the residual transformer that predicts RVQ layers 1..5 from the layers below
(shared/tied projections, 20% text dropout). Validation each epoch: cross-entropy and accuracy."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "residual", help="train the residual transformer", description=DESCRIPTION, epilog=EPILOG
    )
    add_common_arguments(p, creates=False)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_stage("residual", args)
