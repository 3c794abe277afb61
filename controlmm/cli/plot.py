"""``controlmm plot MOTION --out X.png|X.gif|X.mp4``: look at a motion."""

from __future__ import annotations

import argparse
from pathlib import Path

from controlmm.atomic import check_output_file
from controlmm.cli.args import add_force, add_motion_input, motion_options
from controlmm.errors import ControlMMError

HELP = """Plot a motion (.npz, .npy, .bvh, .pt; recorded motion of other skeletons too, see
docs/motion-formats.md).
  .png  skeleton snapshots over time (3-D) and a top view of pelvis, feet and wrists
  .gif / .mp4  a 3-D stick-figure animation with the pelvis trail (20 fps)
Axes are the MuJoCo world's: X forward, Y left, Z up."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot",
        help="plot a motion to PNG or animate it to GIF/MP4",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("motion", help="motion file (.npz, .npy, .bvh, .pt)")
    p.add_argument("--out", required=True, help="output .png, .gif or .mp4")
    add_motion_input(p)
    add_force(p, "--out")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # heavy (torch, matplotlib): imported when the command runs, so that --help stays fast
    from controlmm import motion as motions

    if Path(args.out).suffix.lower() not in (".png", ".gif", ".mp4"):
        raise ControlMMError(
            f"unknown output format '{Path(args.out).suffix or args.out}'; allowed: .png, .gif, .mp4"
        )
    check_output_file(args.out, force=args.force)
    motions.plot_or_animate(motions.load_motion(args.motion, **motion_options(args)), args.out)
    print(f"wrote {args.out}")
    return 0
