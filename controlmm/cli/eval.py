"""``controlmm eval ...``: evaluation commands, one module ``controlmm/cli/eval_<name>.py`` each."""

from __future__ import annotations

import argparse
import importlib

EVAL_SUBCOMMANDS: tuple[str, ...] = ("probes", "quality", "control")
"""Modules ``controlmm.cli.eval_<name>`` that register an ``eval`` subcommand, in ``--help`` order."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval",
        help="evaluate motion: text-adherence probes, quality (FID, R-precision), spatial control",
        description="Evaluate motion data or models. Run 'controlmm eval COMMAND --help'.",
    )
    evsub = p.add_subparsers(dest="eval_command", metavar="COMMAND", parser_class=type(p))
    for name in EVAL_SUBCOMMANDS:
        importlib.import_module(f"controlmm.cli.eval_{name}").register(evsub)

    def usage(args: argparse.Namespace) -> int:
        p.print_help()
        return 2

    p.set_defaults(func=usage)
