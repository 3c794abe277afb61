"""The obstacle geoms of a scene as :class:`SceneSDF <scenes.sdf.scene_sdf.SceneSDF>` sees them.

Which geoms are obstacles (:func:`model_obstacles`), how each is posed (static in the world,
or relative to a mocap body moved by a track), which kind of SDF evaluates it (:data:`KIND`)
and, for meshes and height fields, its :class:`~scenes.sdf.mesh.MeshSDF` with grids that reach
the scene's extent (:func:`scene_extent`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
import torch

from controlmm.errors import ControlMMError
from scenes.sdf import kernels, primitives
from scenes.sdf.mesh import DEFAULT_REACH, MeshSDF, cached_mesh_sdf
from scenes.sdf.topology import heightfield_mesh
from scenes.tracks import MocapTrack

Tensor = torch.Tensor
G = mujoco.mjtGeom


class StartPlace(Protocol):
    """Where a scene's motion starts (world x, y in metres)."""

    @property
    def x(self) -> float: ...

    @property
    def y(self) -> float: ...


class ObstacleScene(Protocol):
    """What :class:`SceneSDF` reads of a scene (:class:`scenes.Scene` has it)."""

    @property
    def start(self) -> StartPlace: ...

    @property
    def model(self) -> mujoco.MjModel: ...

    @property
    def obstacle_geom_ids(self) -> tuple[int, ...]: ...

    @property
    def tracks(self) -> dict[str, MocapTrack]: ...


SUPPORTED = ("plane", "sphere", "capsule", "cylinder", "box", "ellipsoid", "mesh", "hfield")
BOX, CYLINDER, PLANE, ELLIPSOID, MESH = range(5)
"""Geom kinds, in evaluation order (cheap first, so that the costly ones can be culled). BOX is
a box grown by a ball: boxes, spheres and capsules."""
KIND = {
    "box": BOX,
    "sphere": BOX,
    "capsule": BOX,
    "cylinder": CYLINDER,
    "plane": PLANE,
    "ellipsoid": ELLIPSOID,
    "mesh": MESH,
    "hfield": MESH,
}


def geom_type_name(geom_type: int) -> str:
    """MuJoCo geom type as a lower-case name (``box``, ``mesh``, ...)."""
    return mujoco.mjtGeom(int(geom_type)).name.removeprefix("mjGEOM_").lower()


@dataclass(frozen=True)
class ObstacleGeom:
    """One obstacle geom, as the SDF sees it."""

    column: int  # position in geom_ids (the per_geom output's last axis)
    geom_id: int
    type_name: str
    size: np.ndarray  # (3,) geom_size
    rot: np.ndarray  # (3, 3) world-from-geom (static) or body-from-geom (moving)
    pos: np.ndarray  # (3,)
    track: int  # index into the tracks moving obstacles, -1 when static
    mesh: MeshSDF | None = None

    @property
    def kind(self) -> int:
        return KIND[self.type_name]

    def mesh_sdf(self) -> MeshSDF:
        """The :class:`MeshSDF` of a mesh or height-field geom (an error for any other kind)."""
        if self.mesh is None:
            raise RuntimeError(f"geom {self.geom_id} ({self.type_name}) has no mesh SDF")
        return self.mesh


def make_geom(
    model: mujoco.MjModel,
    col: int,
    g: int,
    data: mujoco.MjData,
    body_track: dict[int, int],
    tracks: Sequence[MocapTrack],
    extent: np.ndarray,
    mesh_pad: float,
    mesh_pitch: float,
    convex_hull: bool,
) -> ObstacleGeom:
    """The obstacle geom ``g`` (column ``col`` of the SDF's output) posed by ``data``.

    ``body_track``: mocap body -> index into ``tracks`` (the tracks moving obstacle geoms);
    ``extent``: (2, 3) the scene box a mesh's grids must reach (:func:`scene_extent`);
    ``mesh_pad``, ``mesh_pitch``, ``convex_hull``: see :func:`scenes.sdf.mesh.cached_mesh_sdf`.
    """
    m = model
    type_name = geom_type_name(m.geom_type[g])
    if type_name not in KIND:
        name = m.geom(g).name or f"geom{g}"
        raise ControlMMError(
            f"geom '{name}' has type '{type_name}', which the SDF does not support "
            f"(supported: {', '.join(SUPPORTED)})"
        )
    body = int(m.geom_bodyid[g])
    if body in body_track:  # pose relative to the mocap body, composed with the track at call time
        rot, pos, track = quat_mat(m.geom_quat[g]), m.geom_pos[g].copy(), body_track[body]
    else:
        rot, pos, track = data.geom_xmat[g].reshape(3, 3).copy(), data.geom_xpos[g].copy(), -1
    mesh = None
    if KIND[type_name] == MESH:  # its grids reach every corner of the scene's extent
        centres = (
            [data.geom_xpos[g]]
            if track < 0
            else [
                t_pos + np.linalg.norm(pos) * np.array([sx, sy, sz])
                for t_pos in tracks[track].pos
                for sx in (-1, 1)
                for sy in (-1, 1)
                for sz in (-1, 1)
            ]
        )
        corners = np.array([[x, y, z] for x in extent[:, 0] for y in extent[:, 1] for z in extent[:, 2]])
        reach = max(DEFAULT_REACH, max(float(np.linalg.norm(corners - c, axis=1).max()) for c in centres))
        mesh = geom_mesh(m, g, mesh_pad, mesh_pitch, reach, convex_hull)
    return ObstacleGeom(col, g, type_name, m.geom_size[g].copy(), rot, pos, track, mesh)


def geom_mesh(
    model: mujoco.MjModel, g: int, pad: float, pitch: float, reach: float, convex_hull: bool
) -> MeshSDF:
    """The :class:`MeshSDF` of mesh or height-field geom ``g`` (grids reaching ``reach`` m)."""
    m = model
    name = m.geom(g).name or f"geom{g}"
    if int(m.geom_type[g]) == int(G.mjGEOM_MESH):
        mid = int(m.geom_dataid[g])
        v0, nv = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
        f0, nf = m.mesh_faceadr[mid], m.mesh_facenum[mid]
        vertices, faces = m.mesh_vert[v0 : v0 + nv], m.mesh_face[f0 : f0 + nf]
    else:
        hid = int(m.geom_dataid[g])
        nrow, ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
        adr = int(m.hfield_adr[hid])
        vertices, faces = heightfield_mesh(
            m.hfield_size[hid], nrow, ncol, m.hfield_data[adr : adr + nrow * ncol]
        )
    return cached_mesh_sdf(
        vertices,
        faces,
        convex_hull=convex_hull,
        pad=pad,
        pitch=pitch,
        name=name,
        reach=round(reach, 1),
    )


def geom_constants(
    geoms: Sequence[ObstacleGeom], slices: dict[int, slice], like: Tensor
) -> dict[str, Tensor]:
    """The geoms' constants stacked as tensors of ``like``'s dtype and device.

    ``geoms`` sorted by kind, ``slices``: kind -> its columns; BOX and CYLINDER come first.
    """
    device = like.device

    def floats(values: np.ndarray) -> Tensor:  # in like's dtype and device
        return torch.as_tensor(values, dtype=like.dtype, device=device)

    num_round = slices[CYLINDER].stop
    box, disk, ball = np.zeros((len(geoms), 3)), np.zeros(len(geoms)), np.zeros(len(geoms))
    for i, geom in enumerate(geoms[:num_round]):
        box[i], disk[i], ball[i] = primitives.round_params(geom.type_name, geom.size)
    axes = np.array([geom.size for geom in geoms[slices[ELLIPSOID]]]).reshape(-1, 3)
    spheres = [geom.mesh_sdf().bounding_sphere() for geom in geoms[slices[MESH]]]
    moving = [i for i, geom in enumerate(geoms) if geom.track >= 0]
    c = {
        "rot": floats(np.array([geom.rot for geom in geoms]).reshape(-1, 3, 3)),
        "pos": floats(np.array([geom.pos for geom in geoms]).reshape(-1, 3)),
        "box": floats(box),
        "disk": floats(disk),
        "ball": floats(ball),
        "axes": floats(axes),
        "axes_max": floats(axes.max(-1) if len(axes) else np.zeros(0)),
        "mesh_centre": floats(np.array([s[0] for s in spheres]).reshape(-1, 3)),
        "mesh_radius": floats(np.array([s[1] for s in spheres])),
        "moving": torch.as_tensor(moving, dtype=torch.long, device=device),
        "moving_track": torch.as_tensor([geoms[i].track for i in moving], dtype=torch.long, device=device),
        # kind-sorted position of each geom_ids column
        "order": torch.as_tensor(
            np.argsort([geom.column for geom in geoms]), dtype=torch.long, device=device
        ),
    }
    sb, sc = slices[BOX], slices[CYLINDER]
    c["box_half"], c["box_ball"] = c["box"][sb, :, None].contiguous(), c["ball"][sb, None].contiguous()
    c["cyl_half"], c["cyl_radius"] = c["box"][sc, 2:].contiguous(), c["disk"][sc, None].contiguous()
    c["closest_column"] = (torch.arange(len(geoms), device=device) - num_round).clamp_min(0)
    rot_t = c["rot"].transpose(-1, -2)
    c["table"] = torch.cat(
        [rot_t.reshape(-1, 9), c["pos"], c["box"], c["disk"][:, None]], dim=1
    ).T.contiguous()
    c["frames_weight"], c["frames_bias"] = kernels.stack_frames(rot_t[None], c["pos"][None])
    return c


EXTENT_MARGIN = 1.0
"""Metres added around the obstacles (and start pose) to get the region where meshes' SDFs are
accurate (their grids reach it; see :mod:`scenes.sdf.mesh`)."""


def scene_extent(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geom_ids: Sequence[int],
    tracks: Mapping[str, MocapTrack],
    start: tuple[float, float] | None,
) -> np.ndarray:
    """(2, 3) world box holding the obstacles (every key pose of moving ones), the start pose
    (0 to 2 m high) and ``EXTENT_MARGIN`` around them."""
    points = (
        [] if start is None else [np.array([start[0], start[1], 0.0]), np.array([start[0], start[1], 2.0])]
    )
    for g in geom_ids:
        if model.geom_type[g] == G.mjGEOM_PLANE:
            continue
        rot = data.geom_xmat[g].reshape(3, 3)
        centre = data.geom_xpos[g] + rot @ model.geom_aabb[g, :3]
        half = np.abs(rot) @ model.geom_aabb[g, 3:]
        points += [centre - half, centre + half]
    for name, track in tracks.items():
        body = model.body(name).id
        radius = max(
            [
                float(model.geom_rbound[g]) + float(np.linalg.norm(model.geom_pos[g]))
                for g in geom_ids
                if model.geom_bodyid[g] == body
            ]
            or [0.0]
        )
        points += [track.pos.min(0) - radius, track.pos.max(0) + radius]
    if not points:
        return np.zeros((2, 3))
    pts = np.stack(points)
    return np.stack([pts.min(0) - EXTENT_MARGIN, pts.max(0) + EXTENT_MARGIN])


def quat_mat(quat: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of a MuJoCo quaternion (wxyz)."""
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)


def model_obstacles(model: mujoco.MjModel) -> tuple[int, ...]:
    """Colliding geoms of joint-free bodies, upward planes of static bodies excluded."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    has_joint = np.zeros(model.nbody, dtype=bool)
    for j in range(model.njnt):
        has_joint[model.jnt_bodyid[j]] = True
    articulated = {int(model.body_rootid[b]) for b in np.nonzero(has_joint)[0]}
    ids = []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if int(model.body_rootid[body]) in articulated:
            continue
        if (
            model.geom_type[g] == G.mjGEOM_PLANE
            and model.body_mocapid[body] < 0
            and data.geom_xmat[g].reshape(3, 3)[2, 2] > 1 - 1e-9
        ):
            continue
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            ids.append(g)
    return tuple(ids)
