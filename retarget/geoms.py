"""Collision geometry of a MuJoCo robot as points: what the floor and clearance terms see.

Low-level helpers shared by the robot model (feet), the body-above-floor support points
(:mod:`retarget.bodyfloor`) and the self-clearance capsules (:mod:`retarget.capsules`).
Every point is fixed in its body's frame (metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from retarget.kinematics import Poses, quat_to_mat


@dataclass(frozen=True)
class FloorPoints:
    """Points of a foot's collision geometry, fixed in the foot node's frame.

    ``lowest = z(point) - radius``; spheres and capsule end caps give a point with a radius,
    boxes/cylinders/meshes their corners, rims or hull vertices with radius 0.
    """

    node: int
    points: np.ndarray  # (P, 3)
    radius: np.ndarray  # (P,)
    geoms: tuple[int, ...]

    def world(self, poses: Poses) -> np.ndarray:
        """The points in the world (T, P, 3) in each of ``poses``."""
        rot = poses.rot[:, self.node]
        return poses.pos[:, self.node, None, :] + np.einsum("tij,pj->tpi", rot, self.points)

    def lowest(self, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
        """Height (T,) of the lowest collision point above z = 0 in each of ``poses`` and that
        point's centre (T, 3)."""
        pts = self.world(poses)
        low = pts[..., 2] - self.radius
        i = np.argmin(low, axis=1)
        t = np.arange(len(low))
        return low[t, i], pts[t, i]


def geom_points(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Support points (P, 3) in the body frame and radii (P,) of collision geom ``g``."""
    local, rad = geom_local_points(model, g)
    return model.geom_pos[g] + local @ quat_to_mat(model.geom_quat[g]).T, rad


def geom_local_points(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Support points (P, 3) in the geom's own frame and radii (P,) of collision geom ``g``
    (see :class:`FloorPoints`; none for planes and height fields)."""
    gtype = int(model.geom_type[g])
    size = model.geom_size[g]
    t = mujoco.mjtGeom
    if gtype == int(t.mjGEOM_SPHERE):
        local, rad = np.zeros((1, 3)), np.full(1, size[0])
    elif gtype == int(t.mjGEOM_CAPSULE):
        local, rad = np.array([[0, 0, size[1]], [0, 0, -size[1]]]), np.full(2, size[0])
    elif gtype == int(t.mjGEOM_BOX):
        sgn = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
        local, rad = sgn * size[:3], np.zeros(8)
    elif gtype == int(t.mjGEOM_CYLINDER):
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        ring = np.stack([size[0] * np.cos(ang), size[0] * np.sin(ang), np.zeros_like(ang)], -1)
        local = np.concatenate([ring + [0, 0, size[1]], ring - [0, 0, size[1]]])
        rad = np.zeros(len(local))
    elif gtype == int(t.mjGEOM_ELLIPSOID):
        local = np.concatenate([np.diag(size[:3]), -np.diag(size[:3])])
        rad = np.zeros(6)
    elif gtype == int(t.mjGEOM_MESH):
        mid = model.geom_dataid[g]
        verts = model.mesh_vert[model.mesh_vertadr[mid] : model.mesh_vertadr[mid] + model.mesh_vertnum[mid]]
        try:
            verts = verts[ConvexHull(verts).vertices]
        except Exception:  # noqa: BLE001 - degenerate meshes keep all vertices
            pass
        local, rad = np.asarray(verts, dtype=float), np.zeros(len(verts))
    else:
        return np.zeros((0, 3)), np.zeros(0)
    return local, rad


def collision_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    """Collision geoms (contype or conaffinity set) of a body."""
    return [
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]


_SIGNS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)


def aabb_corners(model: mujoco.MjModel, g: int) -> np.ndarray:
    """The 8 corners (8, 3) of geom ``g``'s bounding box (MuJoCo's ``geom_aabb``) in its body frame."""
    centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
    return model.geom_pos[g] + (centre + _SIGNS * half) @ quat_to_mat(model.geom_quat[g]).T


def excluded_body_pairs(model: mujoco.MjModel) -> set[frozenset[int]]:
    """The body pairs the model's ``<contact><exclude>`` elements keep MuJoCo from colliding
    (``exclude_signature`` packs the two body ids as ``first << 16 | second``)."""
    return {frozenset((int(s >> 16), int(s & 0xFFFF))) for s in model.exclude_signature}
