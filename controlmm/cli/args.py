"""Argument types and shared options of the command line: every check in one place.

The types raise :class:`argparse.ArgumentTypeError`, which the parser prints as one line
naming the option, the bad value and what is allowed (exit code 2), before any work.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TypedDict

from controlmm.seeds import SEED_MAX


def integer(minimum: int | None = None, maximum: int | None = None) -> Callable[[str], int]:
    """An int type with inclusive bounds (``None``: unbounded)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number; got '{text}'") from None
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"must be {_range(minimum, maximum)}; got {text}")
        return value

    parse.__name__ = "integer"
    return parse


def number(
    minimum: float | None = None,
    maximum: float | None = None,
    *,
    above: float | None = None,
    below: float | None = None,
) -> Callable[[str], float]:
    """A finite float type with inclusive bounds and optional exclusive ones (``above``, ``below``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number; got '{text}'") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number; got {text}")
        if above is not None and not value > above:
            raise argparse.ArgumentTypeError(f"must be greater than {above:g}; got {text}")
        if below is not None and not value < below:
            raise argparse.ArgumentTypeError(f"must be less than {below:g}; got {text}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"must be {_range(minimum, maximum)}; got {text}")
        return value

    parse.__name__ = "number"
    return parse


def _range(minimum: float | None, maximum: float | None) -> str:
    if minimum is not None and maximum is not None:
        return f"from {minimum:g} to {maximum:g}"
    return f"at least {minimum:g}" if minimum is not None else f"at most {maximum:g}"


seed = integer(0, SEED_MAX)
"""A random seed: 0 .. 2^63 - 1."""

positive = number(above=0.0)
"""A finite number > 0."""

threads = integer(1)
"""A thread count >= 1."""


def add_force(parser: argparse.ArgumentParser, what: str = "the output") -> None:
    """``--force``: replace ``what`` when it exists (otherwise the command refuses)."""
    parser.add_argument(
        "--force",
        action="store_true",
        help=f"replace {what} when it exists (without it, existing files are never replaced)",
    )


def add_threads(parser: argparse.ArgumentParser, default: int | None, note: str = "") -> None:
    """``--threads N``: torch CPU threads."""
    text = "torch's choice" if default is None else str(default)
    parser.add_argument(
        "--threads", type=threads, default=default, help=f"torch CPU threads (default: {text}){note}"
    )


ROBOT_HELP = (
    "a packaged robot (g1, h1, t1, apollo, berkeley_humanoid, op3: see `controlmm robots`), "
    "a humanoid MJCF .xml (mapped automatically) or a mapping .json"
)


def add_robot(parser: argparse.ArgumentParser, default: str | None = "g1", default_text: str = "") -> None:
    """``--robot NAME|ROBOT.xml|MAPPING.json``: the robot, as everywhere a robot is taken."""
    parser.add_argument(
        "--robot",
        default=default,
        metavar="NAME|ROBOT.xml|MAPPING.json",
        help=f"{ROBOT_HELP} (default: {default_text or default})",
    )


UNIT_CHOICES = ("m", "cm", "mm", "in", "cmu")
"""Length units a recorded motion may declare (``controlmm.motion.formats.conventions.UNITS``)."""


def add_motion_input(parser: argparse.ArgumentParser) -> None:
    """The options of a recorded motion in another convention (``controlmm.motion.load_motion``):
    ``--up``, ``--source-fps``, ``--skeleton-map``, ``--units``."""
    group = parser.add_argument_group(
        "recorded motion (BVH of LAFAN1/CMU/Mixamo/SMPL naming, SMPL/SMPL-H/SMPL-X joint arrays; "
        "docs/motion-formats.md)"
    )
    group.add_argument(
        "--up", choices=("y", "z"), default=None, help="the file's up axis (default: detected from the body)"
    )
    group.add_argument(
        "--source-fps",
        type=number(1.0, 1000.0),
        default=None,
        metavar="FPS",
        help="the file's frame rate (default: the file's; needed for a bare .npy/.pt array)",
    )
    group.add_argument(
        "--skeleton-map",
        default=None,
        metavar="MAP.json",
        help="mapping file for a skeleton of other joint names (SMPL joint -> your joint)",
    )
    group.add_argument(
        "--units",
        choices=UNIT_CHOICES,
        default=None,
        help="the file's length unit (default: detected for BVH; metres for joint arrays)",
    )


class MotionOptions(TypedDict):
    """Keyword arguments of ``controlmm.motion.load_motion`` for a recorded motion."""

    up: str | None
    fps: float | None
    mapping: str | None
    units: str | None


def motion_options(args: argparse.Namespace) -> MotionOptions:
    """``load_motion`` keyword arguments from :func:`add_motion_input`'s options."""
    return MotionOptions(up=args.up, fps=args.source_fps, mapping=args.skeleton_map, units=args.units)
