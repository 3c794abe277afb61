"""``controlmm retarget MOTION --robot g1 --fps 50 --out OUT [--render OUT.mp4]``."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from controlmm.atomic import check_output_file
from controlmm.cli.args import (
    add_force,
    add_motion_input,
    add_robot,
    integer,
    motion_options,
    number,
    positive,
)
from controlmm.cli.gl import import_mujoco
from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld

if TYPE_CHECKING:  # the pipeline imports torch: loaded when the command runs (see run)
    from controlmm.pipeline import CheckedTrajectory

HELP = """Retarget a human motion (HumanML3D 22 joints, Y up) to a humanoid robot.

The motion may be recorded motion of another skeleton (BVH with LAFAN1/CMU/Mixamo/SMPL names,
SMPL/SMPL-H/SMPL-X joint arrays in .npy/.npz/.pt; see --up, --source-fps, --skeleton-map and
docs/motion-formats.md): it is imported into the HumanML3D motion first (20 fps).

The output is checked as `controlmm validate` checks it (on the empty scene, or --check-scene):
where the check fails (a weak ankle's torque, a slide), the motion is retargeted again with
fallback settings (flat or half-rolling contact feet, legs halfway to the robot's
proportions) and the passing output closest to the human is kept (within 25 % of the first
one's fit); one line says which, and OUT.json's metrics.check holds every attempt. The exit
status is 0 either way; --no-check retargets once, unchecked.

Writes OUT.npz (fps, qpos with wxyz quaternion, qvel, joint_names, body_names, body_pos_w,
body_quat_w) and OUT.json (robot, source, scale, fps, metrics), and the formats of --format
(default lafan1), then prints the metrics:
  lafan1       OUT.csv              Unitree LAFAN1-G1 / BeyondMimic rows: root x y z, root quaternion
                                    qx qy qz qw (xyzw), joint angles in MJCF order; no header; --fps
  qpos         OUT_qpos.csv         MuJoCo qpos rows: root x y z, quaternion qw qx qy qz (wxyz), joints
  beyondmimic  OUT_beyondmimic.npz  BeyondMimic training file at 50 fps (quaternions wxyz)
  gmr          OUT.pkl              GMR robot pickle: root_pos, root_rot (xyzw), dof_pos; --fps

--robot takes a packaged robot (g1 = Unitree G1 29-DoF, h1 = Unitree H1, t1 = Booster T1,
apollo = Apptronik Apollo, berkeley_humanoid = Berkeley Humanoid, op3 = Robotis OP3; see
`controlmm robots`), any floating-base humanoid MJCF .xml (its mapping is inferred from the
kinematic tree and geometry) or a mapping .json that names any MJCF (see
docs/retargeting.md). --render draws a video with MuJoCo's
offscreen renderer (MUJOCO_GL=egl unless set: Debian packages libegl1, libegl-mesa0,
libgl1-mesa-dri) and falls back to a matplotlib stick figure when no GL backend loads.

examples:
  controlmm generate --text "a person walks forward" --out walk.npz \
      && controlmm retarget walk.npz --out out/g1_walk
  controlmm retarget motion.npz --robot h1 --fps 30 --out out/h1 --render out/h1.mp4
  controlmm retarget motion.npz --robot my_humanoid.xml --out out/mine
  controlmm retarget motion.npz --robot my_robot_mapping.json --out out/mine
  controlmm retarget lafan1_walk.bvh --format lafan1,beyondmimic,gmr --out out/walk
  controlmm retarget omomo_smplh.npy --source-fps 30 --up z --format all --out out/omomo"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "retarget",
        help="retarget a human motion to a robot (CSV/NPZ/JSON, optional MP4)",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("motion", help="human motion (.npz, .npy, .bvh, .pt)")
    add_robot(p)
    p.add_argument("--fps", type=float, default=50.0, help="output frame rate, 10 to 1000 Hz (default 50)")
    p.add_argument(
        "--out", required=True, help="output prefix: writes OUT.npz, OUT.json and the --format files"
    )
    p.add_argument(
        "--format",
        default="lafan1",
        metavar="FMT[,FMT]",
        help="formats beside OUT.npz/OUT.json: lafan1, qpos, beyondmimic, gmr or all (default lafan1)",
    )
    p.add_argument(
        "--yaw", type=number(), default=0.0, help="start heading in degrees about world Z (default 0: +X)"
    )
    p.add_argument("--x", type=number(), default=0.0, help="start position x in metres (default 0)")
    p.add_argument("--y", type=number(), default=0.0, help="start position y in metres (default 0)")
    p.add_argument(
        "--solver",
        choices=("batched", "mink"),
        default="batched",
        help="batched (all frames at once, default) or mink (per-frame IK; needs mink, daqp)",
    )
    p.add_argument("--render", metavar="VIDEO", help="also write a video (.mp4 or .gif)")
    p.add_argument(
        "--render-width", type=integer(16, 4096), default=480, help="video width in pixels (default 480)"
    )
    p.add_argument(
        "--render-height", type=integer(16, 4096), default=360, help="video height in pixels (default 360)"
    )
    p.add_argument("--render-fps", type=positive, default=25.0, help="video frame rate (default 25)")
    p.add_argument(
        "--render-backend",
        choices=("auto", "mujoco", "stick"),
        default="auto",
        help="auto: MuJoCo, else the stick figure (default); mujoco; stick",
    )
    p.add_argument(
        "--check-scene",
        default="empty",
        metavar="SCENE",
        help="scene (name or MJCF file) in which the output is checked as by `controlmm validate` "
        "(default: empty)",
    )
    p.add_argument(
        "--no-check",
        action="store_true",
        help="skip the check and its fallbacks (faster: retargeting alone)",
    )
    add_motion_input(p)
    add_force(p, "OUT.csv/.npz/.json, the --format files and the video")
    p.set_defaults(func=run)


def _format_metrics(metrics: dict, solver: dict, scale: float) -> str:
    rows = [("scale (human -> robot)", f"{scale:.4f}")]
    for group, v in metrics.get("keypoint_error_mm", {}).items():
        rows.append((f"keypoint error {group} (mm)", f"mean {v['mean']:.1f}  max {v['max']:.1f}"))
    rows.append(("joint-limit violations", str(metrics.get("joint_limit_violations"))))
    rows.append(("floor penetration max (mm)", f"{metrics.get('floor_penetration_max_mm', 0):.2f}"))
    sl = metrics.get("foot_sliding_mm_per_stance", {})
    rows.append(
        (
            "foot sliding per stance (mm)",
            f"mean {sl.get('mean', 0):.1f}  max {sl.get('max', 0):.1f}"
            f"  ({metrics.get('stances', 0)} stances)",
        )
    )
    if "joint_jerk_rms_rad_s3" in metrics:
        rows.append(("joint jerk RMS (rad/s^3)", f"{metrics['joint_jerk_rms_rad_s3']:.1f}"))
        rows.append(("joint velocity max (rad/s)", f"{metrics['joint_velocity_max_rad_s']:.2f}"))
    rows.append(("frames @ fps", f"{metrics.get('frames')} @ {metrics.get('fps'):g}"))
    rows.append(
        (
            "solver",
            f"{solver.get('method')}: {solver.get('iterations')} iterations, "
            f"{solver.get('total_seconds', 0) * 1000:.0f} ms",
        )
    )
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{width}}  {v}" for k, v in rows)


def _format_check(checked: CheckedTrajectory, scene: str) -> str:
    """One line: the check's verdict on the kept output and the fallbacks tried."""
    first = checked.attempts[0]
    if checked.report.passed and checked.fallback is None:
        return f"check ({scene} scene, as controlmm validate): PASSED"
    if checked.report.passed:
        return (
            f"check ({scene} scene, as controlmm validate): PASSED with the fallback '{checked.fallback}' "
            f"(the robot's own settings failed: {', '.join(first.errors)})"
        )
    tried = ", ".join(a.name for a in checked.attempts[1:]) or "none"
    return (
        f"check ({scene} scene, as controlmm validate): FAILED: {', '.join(first.errors)} "
        f"(fallbacks tried: {tried}); the output is written as retargeted"
    )


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() in (".csv", ".npz", ".json"):
        out = out.with_suffix("")
    if args.render and Path(args.render).suffix.lower() not in (".mp4", ".gif"):
        raise ControlMMError(
            f"unknown video format '{Path(args.render).suffix or args.render}'; allowed: .mp4, .gif"
        )
    gl_note = import_mujoco("egl") if args.render else None  # the GL backend is chosen before MuJoCo loads
    # heavy (torch, MuJoCo): imported when the command runs, so that --help stays fast
    import retarget.render  # (the package imports retarget.exports too)
    from controlmm import motion as motions
    from controlmm.pipeline import retarget_checked

    formats = retarget.exports.parse_formats(args.format)
    for path in retarget.exports.output_paths(out, formats):
        check_output_file(path, force=args.force)
    if args.render:
        check_output_file(args.render, force=args.force)

    retarget.check_fps(args.fps)
    motion = motions.load_motion(args.motion, **motion_options(args))
    scale = retarget.robot_scale(args.robot)
    transform = HumanToWorld(scale=scale, yaw=math.radians(args.yaw), translation=(args.x, args.y, 0.0))
    if args.no_check:
        traj = retarget.retarget_motion(
            motion, robot=args.robot, fps=args.fps, transform=transform, solver=args.solver
        )
        checked = None
    else:
        # (a scene that does not load fails before any retargeting)
        checked = retarget_checked(
            motion, args.robot, args.fps, transform, scene=args.check_scene, solver=args.solver
        )
        traj = checked.trajectory
        traj.metrics["check"] = {"scene": args.check_scene, **checked.to_dict()}
    traj.source["path"] = str(args.motion)
    paths = retarget.exports.save_trajectory(traj, out, formats)
    print(
        f"retargeted {motion.num_frames} frames @ {motion.fps:g} fps -> {traj.robot_model().name}, "
        f"{traj.num_frames} frames @ {traj.fps:g} Hz"
    )
    print(_format_metrics(traj.metrics, traj.solver, traj.scale))
    if checked is not None:
        print(_format_check(checked, args.check_scene))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    if args.render:
        backend = args.render_backend
        if gl_note and backend != "stick":
            if backend == "mujoco":
                raise ControlMMError(f"MuJoCo rendering unavailable ({gl_note[:200]})")
            print(
                f"controlmm: MuJoCo rendering unavailable ({gl_note[:160]}); drawing a matplotlib stick "
                "figure instead",
                file=sys.stderr,
            )
            backend = "stick"
        used = retarget.render.render_trajectory(
            traj,
            args.render,
            width=args.render_width,
            height=args.render_height,
            fps=args.render_fps,
            backend=backend,
        )
        print(f"wrote {args.render} ({used})")
    return 0
