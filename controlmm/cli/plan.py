"""``controlmm plan``: text + constraints + scene -> checked robot trajectory (the main job)."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from typing import TYPE_CHECKING

from controlmm.atomic import check_output_dir
from controlmm.cli import STARTED
from controlmm.cli.args import add_force, add_motion_input, add_robot, add_threads, motion_options, number
from controlmm.cli.gl import import_mujoco

if TYPE_CHECKING:
    from controlmm.pipeline import PlanResult


HELP = """Plan a humanoid robot motion in a MuJoCo scene, check it in simulation and export it.

Generates a human motion from the prompt with ControlMM (spatial constraints met by logits and
codebook editing, obstacles avoided through SDF losses of the scene), retargets it to the robot,
replays it in MuJoCo (obstacle/floor penetration, self-collision, joint limits, foot sliding,
inverse dynamics; with --physics last of all an execution in physics by a predictive tracking
controller through the robot's actuators: falls and tracking-error spans) and, when a check
fails, turns every failure into an extra editing loss and generates again, up to --rounds times.
Writes into OUT (complete or not at all; OUT may be new, empty or a previous plan output,
anything else needs --force):

  motion.npz        human motion (HumanML3D joints/features, 20 fps)
  robot.csv         root xyz, root quaternion xyzw, joint angles (rad) per frame (Unitree/BeyondMimic)
  robot.npz/.json   qpos (wxyz), qvel, body poses, fps, joint names; sidecar with placement/metrics
  report.json       passed, max_penetration_m, floor_penetration_m, failures, ... and every round
  render.mp4        the robot in the scene (MuJoCo; a stick figure when no OpenGL backend loads)
  plots/*.png       top view (path, obstacles, targets), clearance per round, sim report, motion
  physics.npz, physics_model.xml, robot_physics.csv
                    with --physics: the executed states and the ctrl of every mj_step, the
                    simulated robot + scene as one MJCF file (replay: docs/simulation-checks.md),
                    the executed motion at 50 fps

With only --out it runs the bundled example: the 'table' scene, its prompt and its right-hand
target beyond the table's edge. With --text and no --control the prompt runs unconstrained
(apart from the obstacles).

With --motion FILE it edits a recorded clip instead of generating (BVH of LAFAN1/CMU/Mixamo/
SMPL naming, SMPL/SMPL-H/SMPL-X joints in .npy/.npz/.pt, a Motion .npz; docs/motion-formats.md):
the clip is encoded with the tokenizer and its tokens are codebook-edited against the scene's
obstacles, --control targets and the simulation feedback, with a closeness term that keeps the
joints as near the clip as the constraints allow. report.json ("clip") and the summary give the
mean and largest joint displacement from the clip; plots/displacement.png shows them per frame.

Exit status: 0 passed, 1 the checks still fail after the last
round (the outputs are written anyway), 2 bad input."""

EPILOG = """examples:
  controlmm plan --out out/plan
  controlmm plan --scene pillars --seed 3 --out out/pillars
  controlmm plan --scene corridor --text "a person walks forward" --rounds 2 --out out/corridor
  controlmm plan --scene my_scene.xml --text "a person walks to the box" --control spec.json --out out/mine
  controlmm plan --motion walk.bvh --scene table --out out/walk_table
  controlmm plan --motion omomo.npy --source-fps 30 --up z --scene pillars --format all --out out/omomo
scenes: controlmm scene list    control spec format: README (Spatial control)"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="plan a robot motion in a scene, check it in MuJoCo, export it (main job)",
        description=HELP,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--out",
        required=True,
        help="output directory: new, empty or a previous plan's (replaced atomically when complete)",
    )
    p.add_argument("--scene", default=None, help="packaged scene name or scene .xml (default: table)")
    p.add_argument("--text", default=None, help="prompt (default: the scene's suggested prompt)")
    p.add_argument(
        "--control",
        default=None,
        metavar="SPEC.json",
        help="spatial control spec (default: the scene's suggested one when --text is not given)",
    )
    p.add_argument(
        "--timeline",
        default=None,
        metavar="TIMELINE.json",
        help="body-part timeline spec instead of --text (see docs/timeline.md)",
    )
    p.add_argument(
        "--motion",
        default=None,
        metavar="FILE",
        help="a recorded clip to edit into the scene instead of generating (see above)",
    )
    p.add_argument(
        "--motion-start",
        type=number(0.0),
        default=0.0,
        metavar="S",
        help="with --motion: where the edited window starts in the clip, seconds (default 0)",
    )
    p.add_argument(
        "--closeness",
        type=number(0.0),
        default=1.0,
        help="with --motion: weight of the term that keeps the joints on the clip (default 1)",
    )
    add_robot(p)
    p.add_argument(
        "--seconds",
        type=float,
        default=None,
        help="motion length, 2 to 9.8 s (default: 6 s; with constraints, 0.5 s past the last one, "
        "at least 2 s and at most 6 s unless a constraint comes later); with --motion the window "
        "of the clip, 2 to 30 s (default: the whole clip)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed, 0 to 2^63 - 1 (default 0)")
    p.add_argument(
        "--rounds", type=int, default=3, help="feedback rounds after the first try, 0 to 10 (default 3)"
    )
    p.add_argument("--preset", default="accurate", help="editing preset: fast, medium, accurate (default)")
    p.add_argument("--model", default=None, help="model directory (default: the embedded default model)")
    p.add_argument(
        "--fps", type=float, default=50.0, help="robot trajectory rate, 10 to 1000 Hz (default 50)"
    )
    p.add_argument(
        "--format",
        default="lafan1",
        metavar="FMT[,FMT]",
        help="robot formats beside robot.npz/robot.json: lafan1 (robot.csv), qpos (robot_qpos.csv), "
        "beyondmimic (robot_beyondmimic.npz, 50 fps), gmr (robot.pkl) or all (default lafan1)",
    )
    p.add_argument(
        "--safe-distance",
        type=float,
        default=0.03,
        help="clearance to keep from obstacles in metres (default 0.03)",
    )
    add_threads(
        p,
        1,
        "; the editing loops are small and sequential: on a busy machine more threads spin-wait "
        "and run slower",
    )
    p.add_argument(
        "--physics",
        action="store_true",
        help="execute every round in MuJoCo physics with the predictive tracking controller as the "
        "last check (slow: seconds per second of motion); writes physics.npz, physics_model.xml, "
        "robot_physics.csv",
    )
    p.add_argument("--no-render", action="store_true", help="skip render.mp4 (the slowest output)")
    p.add_argument("--no-plots", action="store_true", help="skip plots/*.png")
    add_motion_input(p)
    add_force(p, "OUT whatever it holds (never a regular file)")
    p.add_argument("--no-progress", action="store_true", help="no progress lines or bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_output_dir(args.out, kind="plan", force=args.force, make_parents=True)  # before any work
    import_mujoco("egl")
    # heavy (torch, MuJoCo, the models): imported when the command runs, so that --help stays fast
    import torch

    from controlmm.pipeline import DEFAULT_SCENE, PlanConfig, plan, write_plan

    torch.set_num_threads(args.threads)
    config = PlanConfig(
        scene=args.scene or DEFAULT_SCENE,
        text=args.text,
        control=args.control,
        robot=args.robot,
        seconds=args.seconds,
        seed=args.seed,
        rounds=args.rounds,
        preset=args.preset,
        model=args.model,
        fps=args.fps,
        safe_distance_m=args.safe_distance,
        render=not args.no_render,
        plots=not args.no_plots,
        timeline=args.timeline,
        motion=args.motion,
        motion_import=dict(motion_options(args)),
        motion_start=args.motion_start,
        closeness_weight=args.closeness,
        formats=tuple(args.format.split(",")),
    )
    config = replace(config, check=replace(config.check, physics=args.physics))
    progress = not args.no_progress
    before = time.perf_counter() - STARTED  # the command's start-up
    result = plan(config, progress=progress)
    result.timing.start_earlier(before)
    backend = write_plan(result, args.out, progress=progress, force=args.force, parallel=True)
    print(result.report.summary())
    moved = dict(result.displacements()).get(result.best)
    if moved is not None:
        print(moved.summary())
    rounds = len(result.rounds)
    print(
        f"plan: {'PASSED' if result.passed else 'FAILED'} in round {result.best} of {rounds} "
        f"({'passed' if result.rounds[0].passed else 'failed'} before feedback), {result.seconds:.1f} s; "
        f"wrote {args.out}/ (motion.npz, robot.npz, {', '.join(_format_files(config.formats))}, report.json"
        f"{', render.mp4 (' + backend + ')' if backend else ''}{'' if args.no_plots else ', plots/'}"
        f"{', physics.npz, physics_model.xml, robot_physics.csv' if result.report.physics else ''})"
    )
    for name, err in zip(_constraint_names(result), result.final.constraint_errors_m, strict=True):
        print(f"  constraint {name}: {err * 100:.2f} cm")
    print(result.timing.summary())
    sys.stdout.flush()
    return 0 if result.passed else 1


def _format_files(formats: tuple[str, ...]) -> list[str]:
    tails = {"lafan1": ".csv", "qpos": "_qpos.csv", "beyondmimic": "_beyondmimic.npz", "gmr": ".pkl"}
    return [f"robot{tails[f]}" for f in formats]


def _constraint_names(result: PlanResult) -> list[str]:
    if result.spec is None:
        return []
    return [f"{c.joint_name}@{c.frame}" for c in result.spec.constraints]
