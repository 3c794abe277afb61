"""What the browser viewer draws: a JSON document built from a plan (in memory or on disk).

A view holds the scene's geometry once (:func:`scene_geometry`) and, per round, everything that
moves or fails:

* ``geoms`` / ``meshes``: every drawn geom (scene obstacles, floor, robot), its mesh in its own
  frame, its colour, and either its world pose (static) or the moving body it rides on;
* ``rounds[i].poses``: world pose of every moving body (robot bodies and mocap obstacles) per
  robot frame, ``(T, B, 7)`` float32 = position (m) + quaternion (wxyz), base64;
* ``rounds[i].human``: the human skeleton in the world ``(T20, 22, 3)`` float32 (m), 20 fps;
* ``rounds[i].failures``: the report's failures (robot frames, inclusive), ``contacts``: every
  robot/obstacle and robot/floor contact that penetrates (``[frame, x, y, z, depth m, body]``),
  ``clearance`` / ``lowest``: per frame the distance to the nearest obstacle and the lowest robot
  point above the floor (m, None where nothing is near), ``targets``: each constraint's target and
  where its joint got to (world m) with the error;
* ``report``: the chosen round's figures, ``files``: the output files to download.

Arrays travel as base64 little-endian float32 so a 10 s plan of a G1 stays a few hundred kB
besides the robot's meshes.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from controlmm.control.spec import ControlSpec
from controlmm.errors import ControlMMError, InputFileError
from controlmm.frames import HumanToWorld
from controlmm.motion.io import load_motion
from controlmm.motion.skeleton import FPS, JOINT_NAMES, PARENTS
from controlmm.pipeline import PlanResult
from controlmm.studio.geometry import geom_mesh, geom_rgba, visible
from retarget import RobotTrajectory
from scenes import Scene, load_scene

VIEW_FORMAT = "controlmm-view-1"
PENETRATION_KINDS = ("obstacle_penetration", "floor_penetration", "self_collision")


def b64(array: np.ndarray, dtype: str = "<f4") -> str:
    """Base64 of ``array`` as little-endian ``dtype`` (what the page decodes)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


@dataclass(frozen=True)
class RoundInput:
    """One round to draw: the robot trajectory, the human joints, the check report and figures.

    Attributes:
        index: round number (0 = before feedback).
        qpos: (T, nq) robot joint positions at ``fps`` (the scene model's qpos layout).
        fps: robot frame rate (Hz).
        human: (T20, 22, 3) human joints in the human frame (Y up, m), 20 fps.
        report: the round's ``sim.Report.to_dict()`` (``failures``, ``frames``, figures).
        figures: the round's summary (``PlanRound.to_dict()``), or {} when unknown.
        errors_m: per constraint, the distance (m) its joint ended from its target.
    """

    index: int
    qpos: np.ndarray
    fps: float
    human: np.ndarray
    report: dict[str, Any]
    figures: dict[str, Any]
    errors_m: list[float]


def moving_bodies(scene: Scene) -> list[int]:
    """Body ids whose pose changes over a plan: the robot's and the tracked mocap obstacles'."""
    m = scene.model
    robot_roots = {int(m.body_rootid[int(m.geom_bodyid[g])]) for g in scene.robot_geom_ids}
    mocap = {m.body(name).id for name in scene.tracks}
    return [b for b in range(1, m.nbody) if int(m.body_rootid[b]) in robot_roots or b in mocap]


def scene_geometry(scene: Scene) -> dict[str, Any]:
    """The drawn geoms and meshes of ``scene`` (see the module docstring); the robot at its start."""
    m = scene.model
    data = mujoco.MjData(m)
    if scene.robot is not None:
        data.qpos[:] = scene.robot_start_qpos()
    scene.set_time(data, 0.0)
    mujoco.mj_kinematics(m, data)
    bodies = moving_bodies(scene)
    slot = {b: i for i, b in enumerate(bodies)}
    robot, floor = set(scene.robot_geom_ids), set(scene.floor_geom_ids)
    meshes: dict[str, dict[str, str]] = {}
    geoms = []
    for g in range(m.ngeom):
        if not visible(m, g):
            continue
        built = geom_mesh(m, g)
        if built is None:
            continue
        key, (verts, faces) = built
        if key not in meshes:
            wide = len(verts) > np.iinfo(np.uint16).max
            meshes[key] = {"vertices": b64(verts), "faces": b64(faces, "<u4" if wide else "<u2")}
            meshes[key]["index"] = "u4" if wide else "u2"
        body = int(m.geom_bodyid[g])
        entry: dict[str, Any] = {
            "name": scene.geom_name(g),
            "mesh": key,
            "rgba": [round(float(c), 4) for c in geom_rgba(m, g)],
            "kind": "robot" if g in robot else "floor" if g in floor else "obstacle",
            "body_name": m.body(body).name,
        }
        if body in slot:  # pose relative to the moving body
            entry["body"] = slot[body]
            entry["pos"] = [float(v) for v in m.geom_pos[g]]
            entry["quat"] = [float(v) for v in m.geom_quat[g]]
        else:  # static: world pose
            quat = np.empty(4)
            mujoco.mju_mat2Quat(quat, data.geom_xmat[g])
            entry["body"] = -1
            entry["pos"] = [float(v) for v in data.geom_xpos[g]]
            entry["quat"] = [float(v) for v in quat]
        geoms.append(entry)
    start = scene.start
    return {
        "scene": scene.name,
        "robot": scene.robot,
        "geoms": geoms,
        "meshes": meshes,
        "bodies": [m.body(b).name for b in bodies],
        "start": {"x": start.x, "y": start.y, "yaw": start.yaw},
        "start_poses": b64(_poses(m, data, bodies)[None]),
        "floor_z": scene.floor_height,
    }


def _poses(m: mujoco.MjModel, data: mujoco.MjData, bodies: list[int]) -> np.ndarray:
    return np.concatenate([data.xpos[bodies], data.xquat[bodies]], axis=1)  # (B, 7)


def body_poses_and_contacts(
    scene: Scene, qpos: np.ndarray, fps: float, floor_tolerance_m: float = 0.005
) -> tuple[np.ndarray, list[list[float | int | str]]]:
    """Moving-body poses (T, B, 7) of a trajectory and its penetrating contacts.

    Contacts are MuJoCo's between a robot geom and an obstacle geom with negative distance, or a
    floor geom deeper than ``floor_tolerance_m`` (feet standing on the floor touch it by design):
    ``[frame, x, y, z, depth (m, > 0), robot body name]``.
    """
    m = scene.model
    if qpos.ndim != 2 or qpos.shape[1] != m.nq:
        raise ControlMMError(f"trajectory has {qpos.shape[-1]} qpos columns; the scene's robot has {m.nq}")
    data = mujoco.MjData(m)
    bodies = moving_bodies(scene)
    robot = set(scene.robot_geom_ids)
    obstacles, floor = set(scene.obstacle_geom_ids), set(scene.floor_geom_ids)
    poses = np.empty((len(qpos), len(bodies), 7))
    contacts: list[list[float | int | str]] = []
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        scene.set_time(data, t / fps)
        mujoco.mj_fwdPosition(m, data)
        poses[t] = _poses(m, data, bodies)
        for c in data.contact[: data.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            other = g2 if g1 in robot else g1 if g2 in robot else -1
            limit = floor_tolerance_m if other in floor else 0.0 if other in obstacles else math.inf
            if -c.dist <= limit:
                continue
            body = m.body(int(m.geom_bodyid[g1 if g1 in robot else g2])).name
            contacts.append([t, *(round(float(v), 4) for v in c.pos), round(-float(c.dist), 5), body])
    return poses, contacts


def _series(values: Any) -> list[float | None]:
    out: list[float | None] = []
    for v in values if values is not None else []:
        out.append(None if v is None or not math.isfinite(float(v)) else round(float(v), 5))
    return out


def round_view(
    scene: Scene, transform: HumanToWorld, spec: ControlSpec | None, rnd: RoundInput
) -> dict[str, Any]:
    """The moving and failing part of one round (see the module docstring)."""
    floor_tol = rnd.report.get("config", {}).get("floor_penetration_m", 0.005)
    poses, contacts = body_poses_and_contacts(scene, rnd.qpos, rnd.fps, floor_tol)
    human_world = np.asarray(transform.to_world(np.asarray(rnd.human, dtype=np.float64)))
    targets = []
    if spec is not None:
        goal = transform.to_world(spec.human_positions(transform))
        for k, c in enumerate(spec.constraints):
            frame = min(c.frame, len(human_world) - 1)
            targets.append(
                {
                    "joint": c.joint_name,
                    "frame": c.frame,
                    "target": [round(float(v), 5) for v in goal[k]],
                    "achieved": [round(float(v), 5) for v in human_world[frame, c.joint]],
                    "error_m": round(float(rnd.errors_m[k]), 5) if k < len(rnd.errors_m) else None,
                }
            )
    frames = rnd.report.get("frames", {})
    return {
        "index": rnd.index,
        "passed": bool(rnd.report.get("passed", False)),
        "fps": rnd.fps,
        "num_frames": len(rnd.qpos),
        "poses": b64(poses),
        "human": b64(human_world),
        "human_fps": float(FPS),
        "failures": rnd.report.get("failures", []),
        "contacts": contacts,
        "clearance": _series(frames.get("clearance_m")),
        "lowest": _series(frames.get("lowest_height_m")),
        "targets": targets,
        "figures": rnd.figures,
    }


def build_view(
    scene: Scene,
    transform: HumanToWorld,
    spec: ControlSpec | None,
    rounds: list[RoundInput],
    chosen: int,
    report: dict[str, Any],
    files: list[str],
    text: str,
    geometry: str,
) -> dict[str, Any]:
    """The whole view document of a plan; ``geometry`` names its :func:`scene_geometry` document
    (served apart, once per scene and robot: ``GET /api/geometry/{id}``)."""
    check = report.get("config", {})
    return {
        "format": VIEW_FORMAT,
        "scene": scene.name,
        "robot": scene.robot,
        "text": text,
        "passed": bool(report.get("passed", False)),
        "chosen": chosen,
        "geometry": geometry,
        "skeleton": {"joints": list(JOINT_NAMES), "parents": list(PARENTS)},
        "tolerances": {
            "obstacle_penetration_m": check.get("obstacle_penetration_m"),
            "floor_penetration_m": check.get("floor_penetration_m"),
        },
        "rounds": [round_view(scene, transform, spec, r) for r in rounds],
        "rounds_drawn": "all",
        "report": {k: v for k, v in report.items() if k not in ("frames", "rounds")},
        "round_figures": report.get("rounds", []),
        "files": files,
    }


def plan_view(result: PlanResult, files: list[str], geometry: str) -> dict[str, Any]:
    """The view of a plan in memory: every round, each with its own trajectory."""
    rounds = [
        RoundInput(
            index=r.index,
            qpos=r.trajectory.qpos,
            fps=r.trajectory.fps,
            human=r.motion.joints,
            report=r.report.to_dict(),
            figures=r.to_dict(),
            errors_m=list(r.constraint_errors_m),
        )
        for r in result.rounds
    ]
    return build_view(
        result.scene,
        result.transform,
        result.spec,
        rounds,
        result.best,
        result.to_dict(),
        files,
        result.text,
        geometry,
    )


PLAN_FILES = ("report.json", "robot.npz", "motion.npz")
"""The files that make a directory a finished plan output (what :func:`dir_view` reads)."""


def is_plan_dir(path: Path) -> bool:
    return all((path / name).is_file() for name in PLAN_FILES)


def plan_files(path: Path) -> list[str]:
    """Relative names of the downloadable files of a plan directory, sorted (hidden files left out)."""
    return sorted(
        p.relative_to(path).as_posix()
        for p in path.rglob("*")
        if p.is_file() and not any(part.startswith(".") for part in p.relative_to(path).parts)
    )


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputFileError(f"cannot read '{path}': {exc}") from None
    if not isinstance(data, dict):
        raise InputFileError(f"'{path}' is not a JSON object")
    return data


def dir_view(path: str | Path, geometry: Callable[[Scene], str]) -> dict[str, Any]:
    """The view of a finished plan directory (``controlmm plan`` output).

    The directory keeps the chosen round's trajectory only: that round is drawn in 3-D, every
    round's figures come from ``report.json``. ``geometry`` gives the id of a scene's geometry.
    """
    root = Path(path)
    if not is_plan_dir(root):
        raise InputFileError(f"'{root}' is not a plan output (it needs {', '.join(PLAN_FILES)})")
    report = _read_json(root / "report.json")
    settings = _read_json(root / "plan.json") if (root / "plan.json").is_file() else {}
    meta = report.get("plan", {})
    scene_ref = str(settings.get("scene") or meta.get("scene") or "")
    robot = str(settings.get("robot") or meta.get("robot") or "g1")
    scene = load_scene(scene_ref, robot=robot)
    traj = RobotTrajectory.load(root / "robot.npz")
    motion = load_motion(root / "motion.npz")
    tr = meta.get("transform") or {}
    x, y, z = (float(v) for v in tr.get("translation", (0.0, 0.0, 0.0)))
    transform = HumanToWorld(
        scale=float(tr.get("scale", 1.0)), yaw=float(tr.get("yaw", 0.0)), translation=(x, y, z)
    )
    spec = ControlSpec.from_dict(meta["control"]) if meta.get("control") else None
    chosen = int(meta.get("chosen_round", 0))
    figures: dict[str, Any] = next((r for r in report.get("rounds", []) if r.get("round") == chosen), {})
    rnd = RoundInput(
        index=chosen,
        qpos=traj.qpos,
        fps=traj.fps,
        human=motion.joints,
        report=report,
        figures=figures,
        errors_m=list(figures.get("constraint_errors_m", [])),
    )
    text = str(meta.get("text", ""))
    view = build_view(scene, transform, spec, [rnd], chosen, report, plan_files(root), text, geometry(scene))
    view["rounds_drawn"] = "chosen"  # a plan directory keeps the chosen round's trajectory only
    return view
