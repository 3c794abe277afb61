"""``controlmm validate ROBOT.npz|ROBOT.csv --scene ... --robot g1 [--physics] --out report.json``."""

from __future__ import annotations

import argparse
from pathlib import Path

from controlmm.atomic import check_output_file
from controlmm.cli.args import add_force, add_robot, integer, seed
from controlmm.errors import ControlMMError

PHYSICS_FILES = ("physics.npz", "physics_model.xml", "robot_physics.csv")
"""The certificate ``--physics`` writes beside the report (``sim.physics.CERTIFICATE_FILES``)."""

HELP = """Check an existing robot trajectory in a MuJoCo scene (e.g. one written by another
retargeter) with the same kinematic and dynamic checks as `controlmm plan`.

Input: this project's robot.npz, any .npz with qpos (T, nq; root quaternion wxyz) and fps,
a BeyondMimic training .npz (joint_pos, body_pos_w, body_quat_w; joints in MJCF order), a
Unitree LAFAN1-G1 / BeyondMimic CSV (no header; xyz, qx qy qz qw, joints in MJCF order;
give --fps, LAFAN1 is 30; --quat-order wxyz for raw MuJoCo qpos rows), or a GMR robot
pickle (.pkl: root_pos, root_rot xyzw, dof_pos, fps; read by a restricted unpickler that
builds numpy arrays and builtin containers only, since a pickle can run code as it loads).
Writes report.json (--out) and a per-frame plot beside it (report.png), and prints a short
summary.

--physics also executes the trajectory in MuJoCo physics: a predictive controller (sampling
over MuJoCo rollouts, full state knowledge) drives the robot through its own actuators
within their limits, with floor and scene contacts and no external force, and the run fails
on a fall or on spans where the robot cannot follow (tracking_fall, tracking_error). Slow:
seconds of computation per second of motion. Writes beside the report a certificate anyone
can replay: physics_model.xml (robot + scene + actuators, one self-contained MJCF file),
physics.npz (qpos, qvel at every simulation step, the ctrl of every mj_step, timestep) and
robot_physics.csv (the executed motion at 50 fps, LAFAN1-G1 / BeyondMimic layout). See
docs/simulation-checks.md.

Exit status: 0 when every check passes, 1 when the trajectory fails a check, 2 on bad input
(wrong width, NaN, a first pose inside the floor or an obstacle: nothing is written)."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate",
        help="check a robot trajectory in a scene (penetration, limits, sliding, dynamics)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("trajectory", help="robot trajectory (.npz, .csv or .pkl)")
    p.add_argument(
        "--scene",
        default="empty",
        help="scene name (see `controlmm scene list`) or MJCF file (default: empty)",
    )
    add_robot(p, default=None, default_text="the file's robot, else g1")
    p.add_argument(
        "--fps", type=float, default=None, help="frame rate (required for .csv; overrides the file's)"
    )
    p.add_argument(
        "--quat-order",
        choices=("xyzw", "wxyz"),
        default="xyzw",
        help="root quaternion order of a .csv: xyzw (LAFAN1-G1, default) or wxyz (MuJoCo qpos rows)",
    )
    p.add_argument("--out", required=True, help="report .json to write (a .png plot is written beside it)")
    p.add_argument("--no-plot", action="store_true", help="skip the per-frame plot")
    p.add_argument(
        "--physics",
        action="store_true",
        help="also execute the trajectory in MuJoCo physics with the predictive tracking controller "
        "and write physics.npz, physics_model.xml, robot_physics.csv beside the report (slow)",
    )
    p.add_argument(
        "--physics-samples",
        type=integer(2, 4096),
        default=None,
        help="rollouts per planning step of the physics controller (default 64; more: slower, steadier)",
    )
    p.add_argument(
        "--physics-threads",
        type=integer(1, 256),
        default=2,
        help="threads of the physics controller's rollout pool (default 2)",
    )
    p.add_argument(
        "--seed", type=seed, default=0, help="seed of the physics controller's sampling (default 0)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar for the physics check")
    add_force(p, "the report, its plot and the physics files")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise ControlMMError(f"--out must be a .json file; got '{args.out}'")
    check_output_file(out, force=args.force)
    if not args.no_plot:
        check_output_file(out.with_suffix(".png"), force=args.force)
    if args.physics:
        for name in PHYSICS_FILES:
            check_output_file(out.parent / name, force=args.force)
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    import scenes
    import sim.files
    from retarget import DEFAULT_ROBOT

    qpos, fps, file_robot = sim.files.load_qpos(args.trajectory, args.fps, args.quat_order)
    robot = args.robot or file_robot or DEFAULT_ROBOT
    if args.robot and file_robot and Path(file_robot).name != Path(args.robot).name:
        raise ControlMMError(f"--robot {args.robot} does not match the trajectory's robot '{file_robot}'")
    scene = scenes.load_scene(args.scene, robot=robot)
    physics = None
    if args.physics:
        samples = {} if args.physics_samples is None else {"samples": args.physics_samples}
        physics = sim.PhysicsConfig(threads=args.physics_threads, seed=args.seed, **samples)
    report = sim.check_trajectory(
        scene,
        qpos,
        fps,
        sim.CheckConfig(physics=args.physics),
        physics=physics,
        progress=not args.no_progress,
    )
    report.save(out)
    if report.physics is not None:
        sim.save_certificate(report.physics, out.parent)
    if not args.no_plot:
        sim.plot_report(
            report, out.with_suffix(".png"), title=f"{Path(args.trajectory).name} in {scene.name} ({robot})"
        )
    print(report.summary())
    written = [str(out)] + ([] if args.no_plot else [str(out.with_suffix(".png"))])
    if report.physics is not None:
        written += [str(out.parent / name) for name in PHYSICS_FILES]
    print("wrote " + ", ".join(written))
    return 0 if report.passed else 1
