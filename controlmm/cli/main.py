"""Entry point of the ``controlmm`` console script.

Each subcommand lives in its own module under :mod:`controlmm.cli` exposing
``register(subparsers)``; the module list below is the whole command surface. Errors a
user can cause print one line on stderr and exit with code 2.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import sys
import threading
import warnings

from controlmm import __version__
from controlmm.errors import ControlMMError

SUBCOMMANDS: tuple[str, ...] = (
    "plan",
    "studio",
    "view",
    "generate",
    "timeline",
    "train",
    "import_official",
    "corpus",
    "convert",
    "plot",
    "retarget",
    "robots",
    "scene",
    "validate",
    "batch",
    "eval",
    "info",
)
"""Modules of :mod:`controlmm.cli` that register a subcommand, in ``--help`` order."""

EXIT_USAGE = 2


class OneLineParser(argparse.ArgumentParser):
    """An argparse parser whose usage errors are one line (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="controlmm",
        description=(
            "Plan humanoid-robot motion with ControlMM: generate human motion from text and "
            "spatial constraints, keep it clear of scene obstacles, retarget it to a robot, "
            "check it in MuJoCo and export joint trajectories."
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"controlmm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    for name in SUBCOMMANDS:
        importlib.import_module(f"controlmm.cli.{name}").register(sub)
    return parser


def _one_line_warning(
    message: Warning | str, category: type[Warning], *args: object, **kwargs: object
) -> None:
    print(f"controlmm: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)  # --help exits 0; a bad argument exits 2 with one line
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE if args.command is None else 0
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    try:
        return int(args.func(args) or 0)
    except ControlMMError as exc:
        print(f"controlmm: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        target = exc.filename or ""
        print(f"controlmm: error: {exc.strerror or exc}: '{target}'", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("controlmm: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except Exception as exc:  # noqa: BLE001
        if os.environ.get("CONTROLMM_DEBUG"):
            raise
        print(
            f"controlmm: internal error: {type(exc).__name__}: {exc} (set CONTROLMM_DEBUG=1 for a traceback)",
            file=sys.stderr,
        )
        return 1


def entry() -> None:
    """The ``controlmm`` command: :func:`main`, then a quick exit.

    Tearing down an interpreter that imported torch, MuJoCo and matplotlib takes about a second on
    2 cores (module finalisation and the garbage of the models), after every output is written and
    closed. Once the command returns, this flushes the streams, runs the exit handlers (temporary
    folders, logging, multiprocessing) and ends the process without that teardown; a command that
    left other (non-daemon) threads running exits the ordinary way, which waits for them.
    """
    code = main()
    if any(not t.daemon and t is not threading.main_thread() for t in threading.enumerate()):
        sys.exit(code)
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (BrokenPipeError, ValueError):  # a closed pipe: nothing left to say
        pass
    os._exit(code)


if __name__ == "__main__":
    entry()
