"""``controlmm scene list|show|sdf``: browse the scene library and look at scenes and their SDFs."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from controlmm.atomic import check_output_file
from controlmm.cli.args import ROBOT_HELP, add_force, integer, number
from controlmm.errors import ControlMMError

HELP = """Scenes are MuJoCo worlds (Z up, metres) with a floor and static or moving obstacles; the
robot (Unitree G1 by default) is attached by name, MJCF or mapping. SCENE is a packaged scene name (see
'controlmm scene list') or the path of your own MJCF file (no joints: static bodies and mocap
bodies only)."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "scene",
        help="list scenes, render them, plot their SDFs",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = p.add_subparsers(dest="scene_command", metavar="ACTION", parser_class=type(p))

    ls = actions.add_parser(
        "list", help="list the packaged scenes", description="List the packaged scenes with what each tests."
    )
    ls.add_argument(
        "--verbose", "-v", action="store_true", help="also print prompts, controls and start poses"
    )
    ls.set_defaults(func=run_list)

    show = actions.add_parser(
        "show",
        help="render a scene to PNG (perspective + top view)",
        description="Render SCENE with MuJoCo offscreen (MUJOCO_GL=egl unless set) with the robot "
        "standing at the start pose; without a working GL backend, draw matplotlib top and side views "
        "instead.",
    )
    show.add_argument("scene", help="scene name or MJCF file")
    show.add_argument("--out", required=True, help="output .png")
    show.add_argument(
        "--robot",
        default="g1",
        metavar="NAME|ROBOT.xml|MAPPING.json",
        help=f"robot to attach: {ROBOT_HELP}, or 'none' (default g1)",
    )
    show.add_argument(
        "--time", type=number(0.0), default=0.0, help="time (s) on moving obstacles' tracks (default 0)"
    )
    show.add_argument(
        "--width", type=integer(16, 4096), default=800, help="width of each view in pixels (default 800)"
    )
    show.add_argument(
        "--height", type=integer(16, 4096), default=600, help="height of each view in pixels (default 600)"
    )
    add_force(show, "--out")
    show.set_defaults(func=run_show)

    sdf = actions.add_parser(
        "sdf",
        help="plot SDF slices of a scene to PNG",
        description="Plot the scene's obstacle SDF (floor excluded) on a horizontal slice at --height and a "
        "vertical slice through the start pose, for eyeballing.",
    )
    sdf.add_argument("scene", help="scene name or MJCF file")
    sdf.add_argument("--out", required=True, help="output .png")
    sdf.add_argument(
        "--height", type=number(), default=0.5, help="z of the horizontal slice in metres (default 0.5)"
    )
    sdf.add_argument(
        "--y", type=number(), default=None, help="y of the vertical slice (default: the start's y)"
    )
    sdf.add_argument(
        "--time", type=number(0.0), default=0.0, help="time (s) on moving obstacles' tracks (default 0)"
    )
    add_force(sdf, "--out")
    sdf.set_defaults(func=run_sdf)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _check_png(out: str, force: bool) -> None:
    if Path(out).suffix.lower() != ".png":
        raise ControlMMError(f"unknown output format '{Path(out).suffix or out}'; allowed: .png")
    check_output_file(out, force=force)


def run_list(args: argparse.Namespace) -> int:
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    from scenes import list_scenes, load_scene

    rows = []
    for name in list_scenes():
        scene = load_scene(name, robot=None)
        moving = "moving" if scene.tracks else "static"
        rows.append((name, f"{len(scene.obstacle_geom_ids)} geoms, {moving}", scene))
    width = max(len(r[0]) for r in rows)
    for name, info, scene in rows:
        print(f"{name:<{width}}  {info:<18}  {scene.description.split('. ')[0].rstrip('.')}.")
        if args.verbose:
            print(f"{'':<{width}}  prompt : {scene.suggested_prompt}")
            print(f"{'':<{width}}  control: {json.dumps(scene.suggested_control)}")
            print(f"{'':<{width}}  start  : x={scene.start.x:g} y={scene.start.y:g} yaw={scene.start.yaw:g}")
    return 0


def run_show(args: argparse.Namespace) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo's first import: headless rendering
    _check_png(args.out, args.force)
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    import scenes.render
    from retarget import load_robot

    robot = None if args.robot.strip().lower() in ("none", "") else args.robot
    if robot is not None:
        load_robot(robot)  # an unknown robot or a bad mapping fails here, in one line
    scene = scenes.load_scene(args.scene, robot=robot)
    backend = scenes.render.render_scene(scene, args.out, width=args.width, height=args.height, t=args.time)
    if backend != "mujoco":
        print(f"note: {backend.removeprefix('matplotlib (').rstrip(')')}; drew matplotlib views instead")
    print(f"wrote {args.out}")
    return 0


def run_sdf(args: argparse.Namespace) -> int:
    _check_png(args.out, args.force)
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    import scenes.render

    scene = scenes.load_scene(args.scene, robot=None)
    scenes.render.plot_sdf_slice(scene, args.out, height=args.height, t=args.time, y=args.y)
    print(f"wrote {args.out}")
    return 0
