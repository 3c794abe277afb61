"""The three kinds of job, run inside a worker: plan, retarget (+ validate), validate.

Each task takes the job's resolved arguments (:func:`controlmm.batch.payload.payload`: paths
absolute, input files as bytes, the control spec loaded), writes its files into ``out`` (an empty
folder of the worker) and returns the job's figures: ``passed`` (None when nothing was checked)
and the report's numbers (:func:`report_figures`). The worker keeps what is costly to build
(models, scenes with their check worlds) in a :class:`Warm` between jobs.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.batch.payload import WORLD_CACHE
from controlmm.batch.variations import jitter_scene
from controlmm.errors import ControlMMError, InputFileError
from controlmm.frames import HumanToWorld
from controlmm.generate import MotionModel, load_model
from controlmm.motion import Motion, load_motion
from controlmm.pipeline import PlanConfig, plan, retarget_checked, write_plan
from retarget import DEFAULT_ROBOT, load_robot, retarget_motion, robot_scale
from scenes import Scene, load_scene
from sim import CheckWorld, Report, check_trajectory, make_world
from sim.files import load_qpos

HUMAN_CSV_COLUMNS = 22 * 3
"""A ``.csv`` motion with this many columns holds human joints (x y z of the 22 joints, Y up, m)."""

PLAN_OPTIONS = ("text", "control", "timeline", "robot", "seconds", "seed", "rounds", "preset", "model", "fps")
"""Arguments of a plan job passed to :class:`controlmm.pipeline.PlanConfig` as they are."""


@dataclass
class Warm:
    """What a worker keeps between jobs: models by directory, scenes and check worlds by (scene, robot)."""

    models: dict[str | None, MotionModel] = field(default_factory=dict)
    worlds: OrderedDict[tuple[str, str], tuple[Scene, CheckWorld]] = field(default_factory=OrderedDict)

    def model(self, model_dir: str | None) -> MotionModel:
        if model_dir not in self.models:
            self.models[model_dir] = load_model(model_dir)
        return self.models[model_dir]

    def world(self, scene: str, robot: str) -> tuple[Scene, CheckWorld]:
        key = (scene, robot)
        if key not in self.worlds:
            loaded = load_scene(scene, robot=robot)
            self.worlds[key] = (loaded, make_world(loaded))
            while len(self.worlds) > WORLD_CACHE:
                self.worlds.popitem(last=False)
        self.worlds.move_to_end(key)
        return self.worlds[key]


def report_figures(report: Report) -> dict[str, Any]:
    """The figures of a check report that a batch summary lists (metres, frame counts)."""
    kinds: dict[str, int] = {}
    for failure in report.errors:
        kinds[failure.kind] = kinds.get(failure.kind, 0) + 1
    return {
        "passed": bool(report.passed),
        "failure_kinds": kinds,
        "max_penetration_m": round(report.max_penetration_m, 6),
        "floor_penetration_m": round(report.floor_penetration_m, 6),
        "foot_sliding_m": round(report.foot_sliding_m, 6),
        "self_collision_frames": report.self_collision_frames,
        "joint_limit_violations": report.joint_limit_violations,
        "frames": int(report.num_frames),
        "fps": float(report.fps),
        "warnings": len(report.warnings),
    }


def write_input(args: dict[str, Any], key: str, folder: Path) -> Path:
    """Write the shipped input file ``args[key]`` (``{"name", "data"}``) into ``folder``; return it."""
    item = args[key]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / Path(item["name"]).name
    path.write_bytes(item["data"])
    return path


def run_plan(args: dict[str, Any], out: Path, warm: Warm) -> dict[str, Any]:
    """A ``plan`` job: ``controlmm.pipeline.plan`` then ``write_plan`` (no video or plots by default)."""
    figures: dict[str, Any] = {}
    scene = args.get("scene")
    variation = args.get("variation")
    if variation is not None:  # a jittered copy of the scene, kept with the outputs
        xml, moved = jitter_scene(
            variation["scene"],
            index=variation["index"],
            seed=variation["seed"],
            jitter_m=variation["jitter_m"],
        )
        scene_file = out.parent / "in" / f"{Path(str(variation['scene'])).stem}-v{variation['index']}.xml"
        scene_file.parent.mkdir(parents=True, exist_ok=True)
        scene_file.write_text(xml, encoding="utf-8")
        scene = str(scene_file)
        figures.update(scene_file=scene_file.name, obstacle_offsets_m=moved)
    options: dict[str, Any] = {k: args[k] for k in PLAN_OPTIONS if k in args}
    if scene is not None:
        options["scene"] = scene
    if "safe_distance" in args:
        options["safe_distance_m"] = float(args["safe_distance"])
    config = PlanConfig(
        **options, render=bool(args.get("render", False)), plots=bool(args.get("plots", False))
    )
    result = plan(config, model=warm.model(config.model), progress=False)
    write_plan(result, out, progress=False)
    if variation is not None:
        (out / scene_file.name).write_text(xml, encoding="utf-8")
    errors = result.final.constraint_errors_m
    return {
        **report_figures(result.report),
        **figures,
        "input": result.text,
        "constraint_errors_m": [round(e, 5) for e in errors],
        "max_constraint_error_m": round(max(errors), 5) if errors else None,
        "chosen_round": result.best,
        "rounds_run": len(result.rounds),
    }


def run_retarget(args: dict[str, Any], out: Path, warm: Warm) -> dict[str, Any]:
    """A ``retarget`` job: retarget the motion, write robot.csv/npz/json, validate in the scene.

    A ``.csv`` motion of 66 columns holds human joints (at ``csv_fps``); one whose width is the
    robot's (xyz, quaternion xyzw, joints) is already a trajectory of it: it is validated only.
    """
    robot = args.get("robot") or DEFAULT_ROBOT
    path = write_input(args, "motion", out.parent / "in")
    scene_name = args.get("scene") or "empty"
    if path.suffix.lower() == ".csv":
        motion_or_qpos = _csv_input(path, float(args.get("csv_fps", 30.0)), robot)
        if isinstance(motion_or_qpos, np.ndarray):
            _, world = warm.world(scene_name, robot)
            report = check_trajectory(world, motion_or_qpos, float(args.get("csv_fps", 30.0)))
            report.save(out / "report.json")
            return {**report_figures(report), "note": "a robot trajectory: validated only"}
        motion = motion_or_qpos
    else:
        motion = load_motion(path)
    scene, world = warm.world(scene_name, robot)
    if any(k in args for k in ("x", "y", "yaw")):
        transform = HumanToWorld(
            scale=robot_scale(robot),
            yaw=math.radians(float(args.get("yaw", 0.0))),
            translation=(float(args.get("x", 0.0)), float(args.get("y", 0.0)), 0.0),
        )
    else:
        transform = scene.human_to_world(robot_scale(robot))
    fps = float(args.get("fps", 50.0))
    check_report: Report | None = None
    fallback = None
    if args.get("validate", True):  # checked, with the fallback settings where the check fails
        result = retarget_checked(motion, robot, fps, transform, scene=world)
        traj, check_report, fallback = result.trajectory, result.report, result.fallback
        traj.metrics["check"] = {"scene": scene.name, **result.to_dict()}
    else:
        traj = retarget_motion(motion, robot=robot, fps=fps, transform=transform)
    traj.source["path"] = str(args["motion"]["name"])
    traj.save(out / "robot")
    figures: dict[str, Any] = {"passed": None, "frames": traj.num_frames, "fps": traj.fps}
    if check_report is not None:
        check_report.save(out / "report.json")
        figures = {**figures, **report_figures(check_report), "fallback": fallback}
    return figures


def run_validate(args: dict[str, Any], out: Path, warm: Warm) -> dict[str, Any]:
    """A ``validate`` job: check a trajectory (.npz / .csv) in the scene, as ``controlmm validate``."""
    path = write_input(args, "trajectory", out.parent / "in")
    qpos, fps, file_robot = load_qpos(path, args.get("fps"))
    robot = args.get("robot") or file_robot or DEFAULT_ROBOT
    if args.get("robot") and file_robot and Path(file_robot).name != Path(args["robot"]).name:
        raise ControlMMError(f"robot {args['robot']} does not match the trajectory's robot '{file_robot}'")
    _, world = warm.world(args.get("scene") or "empty", robot)
    report = check_trajectory(world, qpos, fps)
    report.save(out / "report.json")
    return {**report_figures(report), "robot": Path(robot).stem}


def _csv_input(path: Path, fps: float, robot: str) -> Motion | np.ndarray:
    """A CSV motion: human joints (66 columns) as a Motion, or the robot's qpos (wxyz) as an array."""
    try:
        rows = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
    except ValueError:  # a header line
        try:
            rows = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2, skiprows=1)
        except ValueError as exc:
            raise InputFileError(f"'{path.name}' is not a numeric CSV ({exc})") from None
    width = int(load_robot(robot).model.nq)  # xyz, quaternion, joints
    if rows.shape[1] == HUMAN_CSV_COLUMNS:
        return Motion(joints=rows.reshape(len(rows), 22, 3), fps=fps, metadata={"source": path.name})
    if rows.shape[1] == width:
        qpos, _, _ = load_qpos(path, fps)
        return qpos
    raise InputFileError(
        f"'{path.name}' has {rows.shape[1]} columns: neither human joints ({HUMAN_CSV_COLUMNS}: x y z of "
        f"22 joints) nor a {Path(robot).stem} trajectory ({width}: xyz, qx qy qz qw, joints)"
    )


TASKS: dict[str, Callable[[dict[str, Any], Path, Warm], dict[str, Any]]] = {
    "plan": run_plan,
    "retarget": run_retarget,
    "validate": run_validate,
}
"""The task of each job kind."""
