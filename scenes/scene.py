"""Scenes: a Z-up MuJoCo world (floor + static or mocap obstacles) with a robot attached.

A scene MJCF holds **no joints**: obstacles sit in static bodies (children of the world
without joints) or in mocap bodies moved along keyframe tracks (:mod:`scenes.tracks`). The robot
(a packaged name, an MJCF path or a mapping ``.json``) is attached from its own MJCF
(``retarget.robot_files.load_robot_spec``) with ``mujoco.MjSpec`` and keeps its joint and body
names, so ``model.nq`` and the qpos layout are the robot's own.

Optional metadata lives in the MJCF's ``<custom>`` section, so a user's own scene file loads
exactly like a packaged one::

    <custom>
      <text name="controlmm.description" data="What the scene tests."/>
      <text name="controlmm.prompt" data="a person walks forward ..."/>
      <text name="controlmm.control" data='{"coords": "world", "constraints": [...]}'/>
      <numeric name="controlmm.start" data="0 0 0"/>          <!-- x y yaw (m, m, rad) -->
      <numeric name="controlmm.track.BODY" data="t x y z qw qx qy qz ..."/>
    </custom>
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

import mujoco
import numpy as np

from controlmm.errors import ControlMMError, InputFileError
from controlmm.frames import HumanToWorld
from retarget.robot_files import compile_robot, load_robot_spec
from scenes.registry import list_scenes, scene_path
from scenes.sdf.scene_sdf import SceneSDF
from scenes.tracks import TRACK_PREFIX, MocapTrack

META = "controlmm."


class StartPose(NamedTuple):
    """Where the motion starts: world x, y (m) and the heading yaw (rad, 0 = facing +X)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


@dataclass
class Scene:
    """A compiled scene (see the module docstring).

    Attributes:
        name: scene name (the file stem for user files).
        path: the scene's MJCF file.
        model: compiled ``mujoco.MjModel``, the robot attached when ``robot`` is set.
        robot: the robot argument (packaged name, MJCF or mapping path) or None.
        description, suggested_prompt: documentation strings ("" when absent).
        suggested_control: control-spec dict (``{"coords": "world", "constraints": [...]}``) or None.
        start: :class:`StartPose` where the motion starts.
        obstacle_geom_ids: colliding geoms that are neither robot nor floor (the SDF's geoms).
        floor_geom_ids: upward-facing plane geoms of static bodies.
        robot_geom_ids: every geom of the robot (visual and collision).
        tracks: keyframe tracks of mocap bodies, by body name.
        spec: the ``mujoco.MjSpec`` ``model`` was compiled from (the physics check saves the
            robot + scene as one MJCF file from it).
    """

    name: str
    path: Path
    model: mujoco.MjModel
    robot: str | None
    description: str
    suggested_prompt: str
    suggested_control: dict | None
    start: StartPose
    obstacle_geom_ids: tuple[int, ...]
    floor_geom_ids: tuple[int, ...]
    robot_geom_ids: tuple[int, ...]
    tracks: dict[str, MocapTrack] = field(default_factory=dict)
    spec: mujoco.MjSpec | None = field(default=None, repr=False, compare=False)
    _sdf: SceneSDF | None = field(default=None, repr=False)

    @property
    def floor_height(self) -> float:
        """World z of the (highest) floor plane; 0.0 when the scene has none."""
        if not self.floor_geom_ids:
            return 0.0
        data = mujoco.MjData(self.model)
        mujoco.mj_kinematics(self.model, data)
        return float(max(data.geom_xpos[g][2] for g in self.floor_geom_ids))

    @property
    def moving_geom_ids(self) -> tuple[int, ...]:
        """Obstacle geoms carried by a tracked mocap body."""
        bodies = {self.model.body(b).id for b in self.tracks}
        return tuple(g for g in self.obstacle_geom_ids if int(self.model.geom_bodyid[g]) in bodies)

    def geom_name(self, geom_id: int) -> str:
        """The geom's name, or ``geom<id>`` when it has none."""
        return self.model.geom(geom_id).name or f"geom{geom_id}"

    def set_time(self, data: mujoco.MjData, t: float) -> None:
        """Move every tracked mocap body to its pose at time ``t`` (s). Call ``mj_kinematics``
        or ``mj_forward`` afterwards to update geom poses and contacts."""
        for body, track in self.tracks.items():
            mocap = self.model.body(body).mocapid[0]
            data.mocap_pos[mocap], data.mocap_quat[mocap] = track.pose_numpy(t)

    def human_to_world(self, scale: float) -> HumanToWorld:
        """The frame transform placing a human motion at this scene's start pose.

        ``scale`` is the retargeter's human -> robot scale (``retarget.robot_scale(robot)``).
        """
        return HumanToWorld(scale=scale, yaw=self.start.yaw, translation=(self.start.x, self.start.y, 0.0))

    def robot_start_qpos(self) -> np.ndarray:
        """qpos (nq,) of the robot standing at the start pose (its first keyframe, else qpos0)."""
        if self.robot is None:
            raise ControlMMError(f"scene '{self.name}' has no robot attached")
        m = self.model
        qpos = (m.key_qpos[0] if m.nkey else m.qpos0).copy()
        half = self.start.yaw / 2
        yaw_q = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, yaw_q, qpos[3:7])
        qpos[0:2] = (self.start.x, self.start.y)
        qpos[3:7] = quat
        return qpos

    def sdf(self) -> SceneSDF:
        """The scene's :class:`scenes.sdf.SceneSDF` (built once, then cached)."""
        if self._sdf is None:
            self._sdf = SceneSDF(self)
        return self._sdf


def load_scene(
    name_or_path: str | Path,
    robot: str | None = "g1",
    edit_spec: Callable[[mujoco.MjSpec], None] | None = None,
) -> Scene:
    """Load a packaged scene by name, or any scene MJCF file, and attach ``robot`` (a packaged
    robot name, a robot MJCF path or a mapping ``.json``).

    ``edit_spec`` may change the ``mujoco.MjSpec`` just before it is compiled (for example
    :func:`scenes.probe.add_probe`); geoms it adds after the scene's keep the scene's geom ids.

    Raises:
        ControlMMError: unknown name (lists the known ones), missing or malformed file (MuJoCo's
            message with file and line), joints in the scene, bad metadata or tracks, unknown robot.
    """
    path = _resolve(name_or_path)
    spec = _spec_from_file(path)
    joints = [j.name or "<unnamed>" for j in spec.joints]
    if joints:
        raise ControlMMError(
            f"scene '{path}' has joints ({', '.join(joints[:5])}); scenes hold static or mocap "
            "obstacles only (attach the robot by name instead)"
        )
    meta = _metadata(spec, path)
    tracks = _tracks(spec, path)
    robot_root = _attach_robot(spec, robot) if robot is not None else None
    if edit_spec is not None:
        edit_spec(spec)
    try:
        model = _compile(spec, path)
    except InputFileError:
        if robot is not None:
            compile_robot(robot)  # the robot's own file at fault (a mesh missing): its own line
        raise
    robot_ids, floor_ids, obstacle_ids = _classify_geoms(model, robot_root)
    return Scene(
        name=path.stem,
        path=path,
        model=model,
        robot=robot,
        tracks=tracks,
        robot_geom_ids=robot_ids,
        floor_geom_ids=floor_ids,
        obstacle_geom_ids=obstacle_ids,
        spec=spec,
        **meta,
    )


def _resolve(name_or_path: str | Path) -> Path:
    text = str(name_or_path)
    packaged = scene_path(text)
    if packaged is not None and not Path(text).suffix:
        return packaged
    path = Path(text)
    if path.suffix.lower() == ".xml" or path.exists() or "/" in text:
        if not path.is_file():
            raise InputFileError(f"scene file '{path}' does not exist")
        return path.resolve()
    raise ControlMMError(
        f"unknown scene '{text}'; known scenes: {', '.join(list_scenes())} (or an MJCF file path)"
    )


def _one_line(message: str) -> str:
    return "; ".join(part.strip() for part in message.splitlines() if part.strip())


def _spec_from_file(path: Path) -> mujoco.MjSpec:
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise InputFileError(f"malformed MJCF '{path}': {_one_line(str(exc))}") from None


def _compile(spec: mujoco.MjSpec, path: Path) -> mujoco.MjModel:
    with _quiet_mujoco():
        try:
            return spec.compile()
        except ValueError as exc:
            raise InputFileError(f"malformed MJCF '{path}': {_one_line(str(exc))}") from None


def _metadata(spec: mujoco.MjSpec, path: Path) -> dict:
    texts = {t.name: t.data for t in spec.texts}
    numerics = {n.name: np.asarray(n.data, dtype=np.float64) for n in spec.numerics}
    control = None
    if f"{META}control" in texts:
        try:
            control = json.loads(texts[f"{META}control"])
        except json.JSONDecodeError as exc:
            raise ControlMMError(
                f"scene '{path}': custom text '{META}control' is not JSON ({exc.msg})"
            ) from None
    start = numerics.get(f"{META}start", np.zeros(3))
    if start.shape != (3,) or not np.all(np.isfinite(start)):
        raise ControlMMError(
            f"scene '{path}': custom numeric '{META}start' must be 3 finite numbers (x y yaw)"
        )
    return {
        "description": texts.get(f"{META}description", ""),
        "suggested_prompt": texts.get(f"{META}prompt", ""),
        "suggested_control": control,
        "start": StartPose(*(float(v) for v in start)),
    }


def _tracks(spec: mujoco.MjSpec, path: Path) -> dict[str, MocapTrack]:
    tracks: dict[str, MocapTrack] = {}
    for numeric in spec.numerics:
        if not numeric.name.startswith(TRACK_PREFIX):
            continue
        body_name = numeric.name[len(TRACK_PREFIX) :]
        body = spec.body(body_name)
        if body is None or not body.mocap:
            raise ControlMMError(
                f"scene '{path}': track '{numeric.name}' needs a mocap body named '{body_name}'"
            )
        track = MocapTrack.from_flat(body_name, np.asarray(numeric.data))
        body.pos, body.quat = track.pose_numpy(float(track.times[0]))  # the model starts on the track
        tracks[body_name] = track
    return tracks


def _attach_robot(spec: mujoco.MjSpec, robot: str) -> str:
    """Attach the robot's body tree (names unchanged); return the name of its root body.

    ``robot`` is a packaged robot name, the path of a robot MJCF (``.xml``) or a mapping
    ``.json`` naming one (:func:`retarget.robot_files.load_robot_spec`: colliders declared).
    """
    robot_spec = load_robot_spec(robot)
    default_opt, scene_opt, robot_opt = mujoco.MjSpec().option, spec.option, robot_spec.option
    for attr in (
        "timestep",
        "integrator",
        "iterations",
        "ls_iterations",
        "cone",
        "impratio",
        "solver",
        "noslip_iterations",
        "gravity",
    ):
        # Physics settings the robot asks for win unless the scene set its own.
        scene_value, default_value = getattr(scene_opt, attr), getattr(default_opt, attr)
        if np.array_equal(np.asarray(scene_value), np.asarray(default_value)):
            setattr(scene_opt, attr, getattr(robot_opt, attr))
    _drop_shared_assets(robot_spec, spec)
    root = robot_spec.worldbody.first_body()
    frame = spec.worldbody.add_frame()
    try:
        with _quiet_mujoco():
            frame.attach_body(root, prefix="", suffix="")
    except ValueError as exc:
        compile_robot(robot)  # a file that does not compile alone: its own one-line error
        raise InputFileError(
            f"robot '{robot}' cannot be placed in the scene: {_one_line(str(exc))}"
        ) from None
    return root.name


def _drop_shared_assets(robot_spec: mujoco.MjSpec, scene_spec: mujoco.MjSpec) -> None:
    """Delete from ``robot_spec`` the materials and textures that the scene names too (in place).

    A robot given by its Menagerie ``scene.xml`` (the robot with a floor and a sky) carries a
    ``groundplane`` texture and material, as the packaged scenes do; attaching would repeat
    the names. Only the robot's body tree is attached, so its floor's assets are not needed,
    and a robot geom naming one of them gets the scene's.
    """
    for ours, theirs in (
        (robot_spec.materials, scene_spec.materials),
        (robot_spec.textures, scene_spec.textures),
    ):
        names = {element.name for element in theirs if element.name}
        for element in list(ours):
            if element.name in names:
                robot_spec.delete(element)


class _quiet_mujoco:
    """Silence MuJoCo's attach warnings (empty prefix on purpose: the robot keeps its names)."""

    def __enter__(self) -> _quiet_mujoco:
        self._old = mujoco.get_mju_user_warning()
        self._messages: list[str] = []
        mujoco.set_mju_user_warning(self._messages.append)
        self._catch = warnings.catch_warnings()
        self._catch.__enter__()
        warnings.filterwarnings("ignore", message=".*empty prefix.*")
        warnings.filterwarnings("ignore", message=".*Attach conflict.*")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self._catch.__exit__(exc_type, exc, traceback)
        mujoco.set_mju_user_warning(self._old)


def _classify_geoms(model: mujoco.MjModel, robot_root: str | None) -> tuple[tuple[int, ...], ...]:
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    root_id = model.body(robot_root).id if robot_root is not None else -1
    robot, floor, obstacles = [], [], []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if root_id >= 0 and int(model.body_rootid[body]) == root_id:
            robot.append(g)
        elif (
            model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE
            and model.body_mocapid[body] < 0
            and data.geom_xmat[g].reshape(3, 3)[2, 2] > 1 - 1e-9
        ):
            floor.append(g)
        elif model.geom_contype[g] or model.geom_conaffinity[g]:
            obstacles.append(g)
    return tuple(robot), tuple(floor), tuple(obstacles)
