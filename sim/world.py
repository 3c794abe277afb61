"""The robot-in-a-scene view the checks work on (:class:`CheckWorld`).

A check needs to know which geoms belong to the robot, which are the floor and which are
obstacles, which robot bodies are feet, the joint limits and the moving obstacles' poses.
:func:`make_world` reads all of that from a compiled ``mujoco.MjModel`` (classifying geoms
itself when the sets are not given) or from anything shaped like ``scenes.Scene``
(``.model``, ``.robot_geom_ids``, ``.floor_geom_ids``, ``.obstacle_geom_ids``, ``.set_time``).

Automatic classification (MuJoCo's collision filtering: contype/conaffinity and the
body tree, MuJoCo documentation, Computation > Collision detection): robot geoms are the collision geoms
whose body's root is the free-joint body; floor geoms are the other plane geoms; obstacles
are every other collision geom (static bodies and mocap bodies alike).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar, cast

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from controlmm.errors import ControlMMError
from retarget.actuators import joint_torque_limits
from sim.geometry import support_heights

_Derived = TypeVar("_Derived")
"""The type of an object :meth:`CheckWorld.derived` builds (a model copy, a table)."""

SetTime = Callable[[mujoco.MjData, float], None]
"""``set_time(data, t_seconds)``: writes the mocap obstacles' poses for time ``t`` into ``data``."""

FOOT_HEIGHT_BAND_M = 0.015
"""Robot bodies whose lowest collision point at ``qpos0`` is within this of the robot's lowest
point are its feet (G1: ankle-roll links; the ankle-pitch links are 2.8 cm higher)."""

_MESH = int(mujoco.mjtGeom.mjGEOM_MESH)
_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)
_FREE = int(mujoco.mjtJoint.mjJNT_FREE)
_HINGE = int(mujoco.mjtJoint.mjJNT_HINGE)
_SLIDE = int(mujoco.mjtJoint.mjJNT_SLIDE)


@dataclass(frozen=True)
class Foot:
    """A robot foot: its body and the collision geoms it stands on."""

    name: str
    body: int
    geoms: np.ndarray


@dataclass(frozen=True)
class Joints:
    """The robot's 1-DoF joints (hinge and slide), in model order; arrays have shape (J,)."""

    names: tuple[str, ...]
    bodies: tuple[str, ...]
    ids: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    limited: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    torque_limit: np.ndarray
    """N m (or N for slides); NaN where the model states none."""


@dataclass
class CheckWorld:
    """A compiled model plus everything the checks need to know about it.

    Attributes:
        model: the compiled robot + scene model (never modified by the checks).
        robot_geoms, floor_geoms, obstacle_geoms: geom ids, (G,), (P,), (O,) int arrays.
            ``robot_geoms`` holds the robot's collision geoms only.
        root_body: the free-joint body of the robot (e.g. ``pelvis``).
        free_joint: id of that free joint; its qpos is ``qpos[qpos_adr:qpos_adr+7]``.
        robot_bodies: ids of the robot's bodies (root first).
        feet: the robot's feet (automatic unless ``foot_bodies`` was given).
        joints: the robot's hinge/slide joints with limits.
        mass: total robot mass (kg).
        set_time: moves mocap obstacles for a time (seconds), or None when nothing moves.
        hull_vertices: convex-hull vertices (V, 3) in the geom frame, per robot mesh geom.
        spec: the ``mujoco.MjSpec`` the model was compiled from, when known (the physics check
            saves the model from it); None for a world made from a bare ``MjModel``.

    Reuse one world across checks of the same scene: the collision and inverse-dynamics
    copies of the model are built on first use and kept (:meth:`derived`).
    """

    model: mujoco.MjModel
    robot_geoms: np.ndarray
    floor_geoms: np.ndarray
    obstacle_geoms: np.ndarray
    root_body: int
    free_joint: int
    robot_bodies: np.ndarray
    feet: tuple[Foot, ...]
    joints: Joints
    mass: float
    set_time: SetTime | None = None
    hull_vertices: dict[int, np.ndarray] = field(default_factory=dict)
    spec: mujoco.MjSpec | None = field(default=None, repr=False)
    _derived: dict = field(default_factory=dict, repr=False)

    def derived(self, key: tuple, build: Callable[[], _Derived]) -> _Derived:
        """A model copy (or other derived object) built once per world and ``key``."""
        if key not in self._derived:
            self._derived[key] = build()
        return cast(_Derived, self._derived[key])

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def root_qpos_adr(self) -> int:
        return int(self.model.jnt_qposadr[self.free_joint])

    @property
    def root_dof_adr(self) -> int:
        return int(self.model.jnt_dofadr[self.free_joint])

    def body_name(self, body: int) -> str:
        return self.model.body(int(body)).name or f"body{int(body)}"

    def geom_label(self, geom: int) -> str:
        """The geom's name, else ``<body name>/geom<i>`` (i = index among the body's geoms)."""
        m = self.model
        name = m.geom(int(geom)).name
        if name:
            return name
        body = int(m.geom_bodyid[geom])
        return f"{self.body_name(body)}/geom{int(geom) - int(m.body_geomadr[body])}"

    def mocap_poses(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Mocap positions (T, nmocap, 3) and quaternions (T, nmocap, 4, wxyz) at ``times``.

        None when the model has no mocap body or no ``set_time`` was given (obstacles keep
        the poses compiled into the model).
        """
        m = self.model
        if self.set_time is None or m.nmocap == 0:
            return None
        data = mujoco.MjData(m)
        pos = np.empty((len(times), m.nmocap, 3))
        quat = np.empty((len(times), m.nmocap, 4))
        for i, t in enumerate(times):
            self.set_time(data, float(t))
            pos[i] = data.mocap_pos
            quat[i] = data.mocap_quat
        return pos, quat


def _as_ids(values: Iterable[int] | None, model: mujoco.MjModel, what: str) -> np.ndarray | None:
    if values is None:
        return None
    ids = np.unique(np.asarray(list(values), dtype=np.int64))
    if ids.size and (ids.min() < 0 or ids.max() >= model.ngeom):
        raise ControlMMError(f"{what} geom ids must be in [0, {model.ngeom}); got {ids.min()}..{ids.max()}")
    return ids


def _collidable(model: mujoco.MjModel) -> np.ndarray:
    """Geoms that take part in collisions: non-zero contype/conaffinity or named in a <pair>."""
    mask = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    if model.npair:
        mask[model.pair_geom1] = True
        mask[model.pair_geom2] = True
    return mask


def _free_joint(model: mujoco.MjModel) -> int:
    free = np.flatnonzero(model.jnt_type == _FREE)
    if free.size == 0:
        raise ControlMMError("the model has no free joint; the checks need a floating-base robot")
    return int(free[0])


def _hulls(model: mujoco.MjModel, geoms: np.ndarray) -> dict[int, np.ndarray]:
    """Convex-hull vertices of mesh geoms, in the geom frame (the compiled mesh frame)."""
    out: dict[int, np.ndarray] = {}
    cache: dict[int, np.ndarray] = {}
    for g in geoms:
        if model.geom_type[g] != _MESH:
            continue
        mesh = int(model.geom_dataid[g])
        if mesh not in cache:
            adr, num = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            verts = np.asarray(model.mesh_vert[adr : adr + num], dtype=np.float64)
            try:
                verts = verts[ConvexHull(verts).vertices]
            except (QhullError, ValueError):  # flat or tiny meshes: keep every vertex
                pass
            cache[mesh] = verts
        out[int(g)] = cache[mesh]
    return out


def _joints(model: mujoco.MjModel, robot_bodies: np.ndarray) -> Joints:
    rows = [
        j
        for j in range(model.njnt)
        if model.jnt_type[j] in (_HINGE, _SLIDE) and model.jnt_bodyid[j] in set(robot_bodies.tolist())
    ]
    dof_adr = np.array([model.jnt_dofadr[j] for j in rows], dtype=np.int64)
    return Joints(
        names=tuple(model.joint(j).name or f"joint{j}" for j in rows),
        bodies=tuple(model.body(int(model.jnt_bodyid[j])).name for j in rows),
        ids=np.array(rows, dtype=np.int64),
        qpos_adr=np.array([model.jnt_qposadr[j] for j in rows], dtype=np.int64),
        dof_adr=dof_adr,
        limited=np.array([bool(model.jnt_limited[j]) for j in rows], dtype=bool),
        lower=np.array([model.jnt_range[j, 0] for j in rows], dtype=np.float64),
        upper=np.array([model.jnt_range[j, 1] for j in rows], dtype=np.float64),
        torque_limit=joint_torque_limits(model, rows),
    )


def _lowest_point(
    model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray, hulls: dict[int, np.ndarray]
) -> np.ndarray:
    """World height of each geom's lowest point, (G,)."""
    return support_heights(
        model,
        geoms,
        data.geom_xpos[geoms][None],
        data.geom_xmat[geoms][None],
        np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]),
        hulls,
    )[0]


def _feet(
    model: mujoco.MjModel,
    robot_geoms: np.ndarray,
    hulls: dict[int, np.ndarray],
    qpos_adr: int,
    foot_bodies: Sequence[str] | None,
) -> tuple[Foot, ...]:
    body_of = model.geom_bodyid[robot_geoms]
    if foot_bodies is not None:
        feet = []
        for name in foot_bodies:
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            geoms = robot_geoms[body_of == body] if body >= 0 else robot_geoms[:0]
            if body < 0 or geoms.size == 0:
                raise ControlMMError(f"foot body '{name}' is not a robot body with collision geoms")
            feet.append(Foot(name, int(body), geoms))
        return tuple(feet)
    data = mujoco.MjData(model)
    data.qpos[qpos_adr + 3 : qpos_adr + 7] = (1.0, 0.0, 0.0, 0.0)
    mujoco.mj_kinematics(model, data)
    low = _lowest_point(model, data, robot_geoms, hulls)
    body_low: dict[int, float] = {}
    for b, z in zip(body_of.tolist(), low.tolist(), strict=True):
        body_low[b] = min(body_low.get(b, np.inf), z)
    floor = min(body_low.values())
    chosen = sorted(b for b, z in body_low.items() if z <= floor + FOOT_HEIGHT_BAND_M)
    return tuple(Foot(model.body(b).name or f"body{b}", b, robot_geoms[body_of == b]) for b in chosen)


def make_world(
    scene_or_model: object,
    *,
    robot_geom_ids: Iterable[int] | None = None,
    floor_geom_ids: Iterable[int] | None = None,
    obstacle_geom_ids: Iterable[int] | None = None,
    set_time: SetTime | None = None,
    foot_bodies: Sequence[str] | None = None,
) -> CheckWorld:
    """Build the :class:`CheckWorld` of a model or a scene.

    Args:
        scene_or_model: a compiled ``mujoco.MjModel`` (robot + scene, one free joint), a
            ``mujoco.MjSpec`` (compiled here and kept), a ``CheckWorld`` (returned as is), or
            an object with ``.model`` and optionally ``.robot_geom_ids``, ``.floor_geom_ids``,
            ``.obstacle_geom_ids``, ``.set_time`` and ``.spec`` (``scenes.Scene``).
        robot_geom_ids, floor_geom_ids, obstacle_geom_ids: explicit geom sets (override both
            the scene's and the automatic classification).
        set_time: ``set_time(data, t)`` moving mocap obstacles (default: the scene's).
        foot_bodies: names of the robot's foot bodies (default: found geometrically).
    """
    if isinstance(scene_or_model, CheckWorld):
        return scene_or_model
    spec: mujoco.MjSpec | None = None
    if isinstance(scene_or_model, mujoco.MjSpec):
        spec = scene_or_model
        try:
            scene_or_model = spec.compile()
        except ValueError as exc:
            raise ControlMMError(f"MuJoCo cannot compile the model: {' '.join(str(exc).split())}") from None
    if isinstance(scene_or_model, mujoco.MjModel):
        model, scene = scene_or_model, None
    elif isinstance(held := getattr(scene_or_model, "model", None), mujoco.MjModel):
        model, scene = held, scene_or_model
    else:
        raise ControlMMError(
            f"expected a mujoco.MjModel or a scene with a .model; got {type(scene_or_model).__name__}"
        )

    def pick(given: Iterable[int] | None, attr: str) -> np.ndarray | None:
        if given is None and scene is not None:
            given = getattr(scene, attr, None)
        return _as_ids(given, model, attr.replace("_geom_ids", ""))

    free = _free_joint(model)
    root = int(model.jnt_bodyid[free])
    root_of = model.body_rootid[model.geom_bodyid]
    collidable = _collidable(model)
    robot = pick(robot_geom_ids, "robot_geom_ids")
    if robot is None:
        robot = np.flatnonzero(root_of == model.body_rootid[root])
    robot = robot[collidable[robot]]
    if robot.size == 0:
        raise ControlMMError("the robot has no collision geoms (contype/conaffinity are all 0)")
    floor = pick(floor_geom_ids, "floor_geom_ids")
    if floor is None:
        floor = np.flatnonzero((model.geom_type == _PLANE) & collidable)
        floor = np.setdiff1d(floor, robot)
    obstacles = pick(obstacle_geom_ids, "obstacle_geom_ids")
    if obstacles is None:
        obstacles = np.setdiff1d(np.flatnonzero(collidable), np.union1d(robot, floor))
    overlap = np.intersect1d(robot, np.union1d(floor, obstacles))
    if overlap.size:
        raise ControlMMError(f"geoms {overlap.tolist()} are both robot and floor/obstacle geoms")
    if set_time is None and scene is not None:
        set_time = getattr(scene, "set_time", None)
    scene_spec = getattr(scene, "spec", None)
    if spec is None and isinstance(scene_spec, mujoco.MjSpec):
        spec = scene_spec

    robot_bodies = np.flatnonzero(model.body_rootid == model.body_rootid[root])
    robot_bodies = np.concatenate([[root], robot_bodies[robot_bodies != root]])
    hulls = _hulls(model, robot)
    return CheckWorld(
        model=model,
        robot_geoms=robot.astype(np.int64),
        floor_geoms=floor.astype(np.int64),
        obstacle_geoms=np.setdiff1d(obstacles, floor).astype(np.int64),
        root_body=root,
        free_joint=free,
        robot_bodies=robot_bodies.astype(np.int64),
        feet=_feet(model, robot, hulls, int(model.jnt_qposadr[free]), foot_bodies),
        joints=_joints(model, robot_bodies),
        mass=float(model.body_subtreemass[root]),
        set_time=set_time,
        hull_vertices=hulls,
        spec=spec,
    )
