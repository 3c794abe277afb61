"""Videos of a robot trajectory: MuJoCo offscreen rendering, or a matplotlib stick figure.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when ``mujoco`` is first imported (the
CLI sets ``MUJOCO_GL=egl`` before that). Headless Linux needs EGL (Debian/Ubuntu packages
``libegl1`` + ``libegl-mesa0`` + ``libgl1-mesa-dri`` for Mesa's software renderer, or an
NVIDIA driver) or OSMesa (``libosmesa6``, ``MUJOCO_GL=osmesa``). Mesa's software EGL takes
about 0.28 s per 640x480 frame on 2 cores, so resolution and frame rate are options. When
no backend loads, :func:`render_trajectory` says why in one line and draws the robot's
bodies as a stick figure with matplotlib instead.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
from tqdm import tqdm

from controlmm.errors import ControlMMError
from controlmm.video import write_video
from retarget.robot_files import read_robot_mjcf
from retarget.robots import robot_scene
from retarget.trajectory import RobotTrajectory


def _scene_model(traj: RobotTrajectory) -> mujoco.MjModel:
    """The robot in a scene with a floor and lights (the Menagerie scene for packaged robots)."""
    robot = traj.robot_model()
    if robot.mapping.source.startswith("packaged:"):
        model = mujoco.MjModel.from_xml_path(str(robot_scene(robot.mapping.robot)))
    else:
        spec = read_robot_mjcf(robot.mjcf)
        light = spec.worldbody.add_light(pos=[0, 0, 3.0], dir=[0, 0, -1])
        if hasattr(mujoco, "mjtLightType"):  # MuJoCo >= 3.3: a light's type replaced ``directional``
            light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
        else:
            light.directional = True
        own_floor = any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.geoms)
        if not own_floor:  # a file with its own floor (the CMU humanoid's) keeps it
            spec.worldbody.add_geom(
                type=mujoco.mjtGeom.mjGEOM_PLANE,
                size=[0, 0, 0.05],
                rgba=[0.6, 0.65, 0.7, 1],
                contype=0,
                conaffinity=0,
            )
        model = spec.compile()
    if model.nq != traj.qpos.shape[1]:
        raise ControlMMError(
            f"the render scene has nq={model.nq} but the trajectory has {traj.qpos.shape[1]}"
        )
    return model


def _frame_indices(traj: RobotTrajectory, fps: float) -> np.ndarray:
    count = max(1, int(np.floor((traj.num_frames - 1) / traj.fps * fps + 1e-9)) + 1)
    return np.clip(np.rint(np.arange(count) / fps * traj.fps).astype(int), 0, traj.num_frames - 1)


def mujoco_frames(
    traj: RobotTrajectory, width: int = 640, height: int = 480, fps: float = 25.0, scene=None
) -> Iterator[np.ndarray]:
    """RGB frames (H, W, 3) from MuJoCo's offscreen renderer, a camera following the root.

    ``scene``: a ``scenes.Scene`` with this robot attached (same qpos layout) to render the robot
    among its obstacles, moving ones at each frame's time; default: the robot's own floor scene.
    """
    if scene is not None and scene.model.nq != traj.qpos.shape[1]:
        raise ControlMMError(
            f"scene '{scene.name}' has nq={scene.model.nq} but the trajectory has "
            f"{traj.qpos.shape[1]}; load the scene with the trajectory's robot"
        )
    model = _scene_model(traj) if scene is None else scene.model
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    data = mujoco.MjData(model)
    renderer = mujoco.Renderer(model, height=height, width=width)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.distance, cam.azimuth, cam.elevation = 3.2 * float(traj.qpos[0, 2]), 135.0, -12.0
    if scene is not None:  # further and higher, so that the obstacles around the robot show
        cam.distance, cam.elevation = 4.5 * float(traj.qpos[0, 2]), -22.0
    idx = _frame_indices(traj, fps)
    root = traj.qpos[idx, 0:3]
    # A smoothed look-at point so that the camera does not shake with the pelvis.
    kernel = np.ones(9) / 9
    look = np.stack(
        [np.convolve(np.pad(root[:, c], 4, mode="edge"), kernel, mode="valid") for c in range(3)], 1
    )
    try:
        for i, t in enumerate(idx):
            data.qpos[:] = traj.qpos[t]
            if scene is not None:
                scene.set_time(data, t / traj.fps)
            mujoco.mj_forward(model, data)
            cam.lookat[:] = [look[i, 0], look[i, 1], 0.75 * traj.qpos[0, 2]]
            renderer.update_scene(data, camera=cam)
            # Shadows and reflections cost ~2/3 of the time with Mesa's software renderer.
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            yield renderer.render().copy()
    finally:
        renderer.close()


def stick_frames(
    traj: RobotTrajectory, width: int = 640, height: int = 480, fps: float = 25.0
) -> Iterator[np.ndarray]:
    """RGB frames of the robot's bodies as a 3-D stick figure (parent -> child lines)."""
    # heavy, and only the stick-figure fallback draws with it (Agg: no display needed)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    robot = traj.robot_model()
    model = robot.model
    names, pos, _ = traj.body_poses()
    parents = [int(model.body_parentid[b]) - 1 for b in range(1, model.nbody)]  # -1: world
    idx = _frame_indices(traj, fps)
    lo, hi = pos.reshape(-1, 3).min(0), pos.reshape(-1, 3).max(0)
    centre, half = (lo + hi) / 2, max((hi - lo)[:2].max() / 2, 0.8) + 0.2
    fig = Figure(figsize=(width / 100, height / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(projection="3d")
    try:
        for t in idx:
            ax.cla()
            ax.set_xlim(centre[0] - half, centre[0] + half)
            ax.set_ylim(centre[1] - half, centre[1] + half)
            ax.set_zlim(0, max(1.5, hi[2] + 0.1))
            ax.set_box_aspect((1, 1, max(1.5, hi[2] + 0.1) / (2 * half)))
            ax.set_xlabel("X fwd (m)")
            ax.set_ylabel("Y left (m)")
            ax.set_zlabel("Z up (m)")
            ax.view_init(elev=15, azim=-60)
            xx, yy = np.meshgrid([centre[0] - half, centre[0] + half], [centre[1] - half, centre[1] + half])
            ax.plot_surface(xx, yy, np.zeros_like(xx), color="#cccccc", alpha=0.3)
            p = pos[t]
            for b, par in enumerate(parents):
                if par >= 0:
                    ax.plot(*zip(p[par], p[b], strict=True), color="#1f77b4", lw=2)
            ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=6, color="#d62728")
            ax.set_title(f"{robot.name}  t = {t / traj.fps:.2f} s (stick figure)")
            canvas.draw()
            yield np.asarray(canvas.buffer_rgba())[..., :3].copy()
    finally:
        fig.clear()


def render_trajectory(
    traj: RobotTrajectory,
    path: str | Path,
    width: int = 640,
    height: int = 480,
    fps: float = 25.0,
    backend: str = "auto",
    progress: bool = True,
    scene=None,
) -> str:
    """Write a video of ``traj`` to ``path`` (.mp4 or .gif); returns the backend used.

    ``backend``: ``"mujoco"``, ``"stick"`` or ``"auto"`` (MuJoCo, falling back to the stick
    figure with a one-line message on stderr when no OpenGL backend loads). ``scene``: render
    in this ``scenes.Scene`` (MuJoCo backend; the stick figure draws the robot alone).
    """
    if backend not in ("auto", "mujoco", "stick"):
        raise ControlMMError(f"unknown render backend '{backend}'; allowed: auto, mujoco, stick")
    for name, value, lo, hi in (
        ("width", width, 16, 3840),
        ("height", height, 16, 2160),
        ("render fps", fps, 1, 120),
    ):
        if not (lo <= value <= hi):
            raise ControlMMError(f"{name} {value} is out of range; allowed {lo} to {hi}")
    count = len(_frame_indices(traj, fps))
    if backend in ("auto", "mujoco"):
        gl = os.environ.get("MUJOCO_GL", "") or "default"
        try:
            gen = mujoco_frames(traj, width, height, fps, scene=scene)
            first = next(gen)
        except Exception as exc:  # noqa: BLE001 - any GL failure means: fall back
            reason = " ".join(str(exc).split()) or type(exc).__name__
            if backend == "mujoco":
                raise ControlMMError(f"MuJoCo rendering failed (MUJOCO_GL={gl}): {reason}") from None
            print(
                f"controlmm: MuJoCo rendering unavailable (MUJOCO_GL={gl}: {reason[:160]}); "
                "drawing a matplotlib stick figure instead",
                file=sys.stderr,
            )
        else:

            def frames() -> Iterator[np.ndarray]:
                yield first
                yield from gen

            write_video(path, _progress(frames(), count, progress, "render (mujoco)"), fps)
            return "mujoco"
    write_video(
        path, _progress(stick_frames(traj, width, height, fps), count, progress, "render (stick)"), fps
    )
    return "stick"


def _progress(frames: Iterator[np.ndarray], total: int, enabled: bool, desc: str) -> Iterator[np.ndarray]:
    if not enabled:
        return frames
    return iter(tqdm(frames, total=total, desc=desc, unit="frame", leave=False))
