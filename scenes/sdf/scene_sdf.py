"""SceneSDF: the signed distance from world points to a scene's obstacles, in torch.

``SceneSDF(scene)(points, t)`` is the minimum over the scene's obstacle geoms (every colliding
geom that is neither part of the robot nor an upward floor plane; the floor has its own loss)
of the geom's signed distance, evaluated in the geom's frame:

* primitives (plane, sphere, capsule, cylinder, box, ellipsoid): analytic, exact
  (:mod:`scenes.sdf.primitives`);
* meshes and height fields: exact point-triangle distances (:mod:`scenes.sdf.mesh`). A mesh's
  SDF is the distance to the mesh itself (concavities included) while MuJoCo collides its
  convex hull; pass ``convex_hull_meshes=True`` to get the simulator's view instead.

Shapes: points (..., N, 3) world metres; ``t`` None (obstacles at their first track pose) or
frame times in seconds broadcastable to ``points.shape[:-2]``, e.g. (T,) for (B, T, N, 3); mocap
obstacles then take their track pose at each frame's time. Output (..., N) metres, negative
inside an obstacle, +inf when the scene has no obstacles. Differentiable in ``points``; any
float dtype and device.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from controlmm.errors import ControlMMError, ShapeError
from scenes.sdf import primitives
from scenes.sdf.mesh import DEFAULT_PAD, DEFAULT_PITCH, MeshSDF, cached_mesh_sdf, heightfield_mesh
from scenes.tracks import MocapTrack, quat_to_mat

Tensor = torch.Tensor
G = mujoco.mjtGeom

PRIMITIVES = {
    int(G.mjGEOM_PLANE): primitives.sdf_plane,
    int(G.mjGEOM_SPHERE): primitives.sdf_sphere,
    int(G.mjGEOM_CAPSULE): primitives.sdf_capsule,
    int(G.mjGEOM_CYLINDER): primitives.sdf_cylinder,
    int(G.mjGEOM_BOX): primitives.sdf_box,
    int(G.mjGEOM_ELLIPSOID): primitives.sdf_ellipsoid,
}
TRIANGULATED = (int(G.mjGEOM_MESH), int(G.mjGEOM_HFIELD))
SUPPORTED = ("plane", "sphere", "capsule", "cylinder", "box", "ellipsoid", "mesh", "hfield")


def geom_type_name(geom_type: int) -> str:
    return mujoco.mjtGeom(int(geom_type)).name.removeprefix("mjGEOM_").lower()


@dataclass
class _Block:
    """Geoms evaluated together: one primitive type (static or moving), or one mesh."""

    columns: list[int]  # positions in the output's last axis
    geom_type: int
    sizes: np.ndarray  # (G, 3)
    rot: np.ndarray  # (G, 3, 3) world-from-geom (static) or body-from-geom (moving)
    pos: np.ndarray  # (G, 3)
    track: list[MocapTrack] | None = None  # per geom, for moving blocks
    mesh: MeshSDF | None = None


class SceneSDF:
    """Signed distance to a scene's obstacles (see the module docstring).

    Args:
        scene: a :class:`scenes.Scene`, or a compiled ``mujoco.MjModel`` (then the obstacles are
            the colliding geoms of joint-free bodies other than upward floor planes).
        geom_ids: override the obstacle geoms.
        tracks: mocap tracks by body name (taken from the scene when it is a Scene).
        convex_hull_meshes: use meshes' convex hulls (what MuJoCo collides) instead of the meshes.
        mesh_pad, mesh_pitch: extent and node spacing of the meshes' candidate grids (m).
    """

    def __init__(self, scene, geom_ids: Sequence[int] | None = None,
                 tracks: Mapping[str, MocapTrack] | None = None, convex_hull_meshes: bool = False,
                 mesh_pad: float = DEFAULT_PAD, mesh_pitch: float = DEFAULT_PITCH) -> None:
        if isinstance(scene, mujoco.MjModel):
            model = scene
            ids = _model_obstacles(model) if geom_ids is None else geom_ids
            tracks = dict(tracks or {})
        else:
            model = scene.model
            ids = scene.obstacle_geom_ids if geom_ids is None else geom_ids
            tracks = dict(scene.tracks if tracks is None else tracks)
        self.model = model
        self.geom_ids = tuple(int(g) for g in ids)
        self.tracks = tracks
        self.convex_hull_meshes = convex_hull_meshes
        data = mujoco.MjData(model)
        for body, track in tracks.items():
            mocap = model.body(body).mocapid[0]
            data.mocap_pos[mocap], data.mocap_quat[mocap] = track.pose_numpy(float(track.times[0]))
        mujoco.mj_kinematics(model, data)
        track_of_body = {model.body(name).id: track for name, track in tracks.items()}
        self._blocks = self._make_blocks(data, track_of_body, mesh_pad, mesh_pitch)
        self._consts: dict[tuple[torch.dtype, torch.device], list[dict[str, Tensor]]] = {}

    @property
    def num_geoms(self) -> int:
        return len(self.geom_ids)

    @property
    def is_moving(self) -> bool:
        return any(b.track is not None for b in self._blocks)

    def _make_blocks(self, data: mujoco.MjData, track_of_body: dict[int, MocapTrack],
                     mesh_pad: float, mesh_pitch: float) -> list[_Block]:
        m = self.model
        groups: dict[tuple[int, bool], list[int]] = {}
        blocks: list[_Block] = []
        for col, g in enumerate(self.geom_ids):
            gtype = int(m.geom_type[g])
            if gtype not in PRIMITIVES and gtype not in TRIANGULATED:
                name = m.geom(g).name or f"geom{g}"
                raise ControlMMError(f"geom '{name}' has type '{geom_type_name(gtype)}', which the SDF does not "
                                     f"support (supported: {', '.join(SUPPORTED)})")
            moving = int(m.geom_bodyid[g]) in track_of_body
            if gtype in TRIANGULATED:
                blocks.append(self._geom_block([col], gtype, data, track_of_body, moving,
                                               mesh=self._mesh(g, mesh_pad, mesh_pitch)))
            else:
                groups.setdefault((gtype, moving), []).append(col)
        for (gtype, moving), cols in groups.items():
            blocks.append(self._geom_block(cols, gtype, data, track_of_body, moving))
        return blocks

    def _geom_block(self, cols: list[int], gtype: int, data: mujoco.MjData,
                    track_of_body: dict[int, MocapTrack], moving: bool, mesh: MeshSDF | None = None) -> _Block:
        m = self.model
        ids = [self.geom_ids[c] for c in cols]
        if moving:  # pose relative to the mocap body, composed with the track at call time
            rot = np.stack([_quat_mat(m.geom_quat[g]) for g in ids])
            pos = np.stack([m.geom_pos[g] for g in ids])
            track = [track_of_body[int(m.geom_bodyid[g])] for g in ids]
        else:
            rot = np.stack([data.geom_xmat[g].reshape(3, 3) for g in ids])
            pos = np.stack([data.geom_xpos[g] for g in ids])
            track = None
        return _Block(cols, gtype, np.stack([m.geom_size[g] for g in ids]), rot, pos, track, mesh)

    def _mesh(self, g: int, pad: float, pitch: float) -> MeshSDF:
        m = self.model
        name = m.geom(g).name or f"geom{g}"
        if int(m.geom_type[g]) == int(G.mjGEOM_MESH):
            mid = int(m.geom_dataid[g])
            v0, nv = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            f0, nf = m.mesh_faceadr[mid], m.mesh_facenum[mid]
            vertices, faces = m.mesh_vert[v0:v0 + nv], m.mesh_face[f0:f0 + nf]
        else:
            hid = int(m.geom_dataid[g])
            nrow, ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
            adr = int(m.hfield_adr[hid])
            vertices, faces = heightfield_mesh(m.hfield_size[hid], nrow, ncol, m.hfield_data[adr:adr + nrow * ncol])
        return cached_mesh_sdf(vertices, faces, convex_hull=self.convex_hull_meshes, pad=pad, pitch=pitch, name=name)

    def _tensors(self, like: Tensor) -> list[dict[str, Tensor]]:
        key = (like.dtype, like.device)
        if key not in self._consts:
            to = dict(dtype=like.dtype, device=like.device)
            self._consts[key] = [{
                "size": torch.as_tensor(b.sizes, **to),
                "rot": torch.as_tensor(b.rot, **to),
                "pos": torch.as_tensor(b.pos, **to),
                "offset": torch.einsum("gi,gij->gj", torch.as_tensor(b.pos, **to), torch.as_tensor(b.rot, **to)),
            } for b in self._blocks]
        return self._consts[key]

    def __call__(self, points: Tensor, t: Tensor | np.ndarray | float | None = None) -> Tensor:
        """Scene SDF (..., N) of world points (..., N, 3) at frame times ``t`` (see module doc)."""
        per_geom = self.per_geom(points, t)
        if per_geom.shape[-1] == 0:
            return torch.full(per_geom.shape[:-1], float("inf"), dtype=points.dtype, device=points.device)
        return per_geom.amin(dim=-1)

    def per_geom(self, points: Tensor, t: Tensor | np.ndarray | float | None = None) -> Tensor:
        """Signed distance to each obstacle geom, (..., N, G), columns in ``geom_ids`` order."""
        points = _check_points(points)
        lead, n = points.shape[:-2], points.shape[-2]
        times = None if t is None else _check_times(t, lead, points)
        consts = self._tensors(points)
        flat = points.reshape(-1, 3)
        out: list[Tensor | None] = [None] * len(self.geom_ids)
        for block, c in zip(self._blocks, consts):
            if block.track is None:
                # local = R^T (x - c) for every geom at once: (M, G, 3)
                local = torch.einsum("mi,gij->mgj", flat, c["rot"]) - c["offset"]
                local = local.reshape(*lead, n, len(block.columns), 3)
            else:
                rot, pos = self._moving_pose(block, c, times, points)  # (..., G, 3, 3), (..., G, 3)
                local = (torch.einsum("...ni,...gij->...ngj", points, rot)
                         - torch.einsum("...gi,...gij->...gj", pos, rot)[..., None, :, :])
            if block.mesh is not None:
                values = block.mesh(local[..., 0, :])[..., None]
            else:
                values = PRIMITIVES[block.geom_type](local, c["size"])
            for k, col in enumerate(block.columns):
                out[col] = values[..., k]
        if not out:
            return points.new_zeros((*lead, n, 0))
        return torch.stack(out, dim=-1)

    def _moving_pose(self, block: _Block, c: dict[str, Tensor], times: Tensor | None,
                     like: Tensor) -> tuple[Tensor, Tensor]:
        rots, poss = [], []
        lead = like.shape[:-2]
        for k, track in enumerate(block.track):
            tt = (torch.full(lead, float(track.times[0]), dtype=like.dtype, device=like.device)
                  if times is None else times)
            body_pos, body_quat = track.pose(tt)
            body_rot = quat_to_mat(body_quat)
            rots.append(body_rot @ c["rot"][k])
            poss.append(body_pos + (body_rot @ c["pos"][k][:, None])[..., 0])
        return torch.stack(rots, dim=-3), torch.stack(poss, dim=-2)


def _quat_mat(quat: np.ndarray) -> np.ndarray:
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)


def _check_points(points) -> Tensor:
    if not isinstance(points, Tensor):
        points = torch.as_tensor(np.asarray(points, dtype=np.float64))
    if points.ndim < 2 or points.shape[-1] != 3:
        raise ShapeError(f"points must have shape (..., N, 3); got {tuple(points.shape)}")
    if not points.is_floating_point():
        points = points.to(torch.get_default_dtype())
    if not bool(torch.isfinite(points.detach()).all()):
        raise ShapeError("points hold NaN or inf; the SDF needs finite world coordinates (m)")
    return points


def _check_times(t, lead: torch.Size, like: Tensor) -> Tensor:
    times = torch.as_tensor(t, dtype=like.dtype, device=like.device)
    if not bool(torch.isfinite(times).all()):
        raise ShapeError("frame times hold NaN or inf")
    try:
        return torch.broadcast_to(times, lead)
    except RuntimeError:
        raise ShapeError(f"frame times of shape {tuple(times.shape)} do not broadcast to the points' leading "
                         f"shape {tuple(lead)} (points (..., N, 3), times (...))") from None


def _model_obstacles(model: mujoco.MjModel) -> tuple[int, ...]:
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
        if (model.geom_type[g] == G.mjGEOM_PLANE and model.body_mocapid[body] < 0
                and data.geom_xmat[g].reshape(3, 3)[2, 2] > 1 - 1e-9):
            continue
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            ids.append(g)
    return tuple(ids)
