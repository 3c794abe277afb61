"""MuJoCo geoms as triangle meshes for the browser viewer.

Every drawn geom becomes vertices (V, 3) float32 and triangles (F, 3) uint32 in the geom's own
frame (metres), with its size baked in; the viewer places them with the geom's pose. Primitives
are tessellated here (boxes, spheres, ellipsoids, capsules, cylinders, planes); mesh geoms keep
MuJoCo's compiled vertices (already in the geom frame). Meshes are shared between geoms by key.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

PLANE_HALF_SIZE_M = 6.0
"""Half size of a drawn infinite plane (MuJoCo size 0)."""

VISIBLE_GROUPS = 3
"""Geom groups 0..2 are drawn (MuJoCo's viewer shows these by default; robots keep their
collision geoms in group 3)."""

_SEGMENTS = 16  # around the axis of round primitives
_RINGS = 8  # from pole to pole of a sphere

GeomMesh = tuple[np.ndarray, np.ndarray]
"""(vertices (V, 3) float32 in metres, triangles (F, 3) uint32)."""


def visible(model: mujoco.MjModel, geom: int) -> bool:
    """Whether ``geom`` is drawn: a visible group and not fully transparent."""
    return int(model.geom_group[geom]) < VISIBLE_GROUPS and float(geom_rgba(model, geom)[3]) > 0.0


def geom_rgba(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(4,) colour of a geom: its material's when it has one, else its own rgba."""
    mat = int(model.geom_matid[geom])
    return np.asarray(model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom], dtype=np.float64)


def geom_mesh(model: mujoco.MjModel, geom: int) -> tuple[str, GeomMesh] | None:
    """(key, mesh) of ``geom`` in its frame, or None for a type that is not drawn (hfield, sdf)."""
    kind = int(model.geom_type[geom])
    size = np.asarray(model.geom_size[geom], dtype=np.float64)
    t = mujoco.mjtGeom
    if kind == t.mjGEOM_MESH:
        mesh = int(model.geom_dataid[geom])
        a, n = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        fa, fn = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
        verts = np.asarray(model.mesh_vert[a : a + n], dtype=np.float32)
        faces = np.asarray(model.mesh_face[fa : fa + fn], dtype=np.uint32)
        return f"mesh:{mesh}", (verts, faces)
    key = f"{kind}:" + ",".join(f"{s:.5g}" for s in size)
    if kind == t.mjGEOM_BOX:
        return key, box(size)
    if kind == t.mjGEOM_SPHERE:
        return key, ellipsoid(np.full(3, size[0]))
    if kind == t.mjGEOM_ELLIPSOID:
        return key, ellipsoid(size)
    if kind == t.mjGEOM_CAPSULE:
        return key, capsule(size[0], size[1])
    if kind == t.mjGEOM_CYLINDER:
        return key, cylinder(size[0], size[1])
    if kind == t.mjGEOM_PLANE:
        hx = size[0] if size[0] > 0 else PLANE_HALF_SIZE_M
        hy = size[1] if size[1] > 0 else PLANE_HALF_SIZE_M
        return key, plane(hx, hy)
    return None


def box(half: np.ndarray) -> GeomMesh:
    """A box with half sizes ``half`` (3,), centred at the origin."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    faces = [
        (0, 1, 3, 2),  # -x
        (4, 6, 7, 5),  # +x
        (0, 4, 5, 1),  # -y
        (2, 3, 7, 6),  # +y
        (0, 2, 6, 4),  # -z
        (1, 5, 7, 3),  # +z
    ]
    tris = [(a, b, c) for a, b, c, d in faces] + [(a, c, d) for a, b, c, d in faces]
    return (corners * half).astype(np.float32), np.asarray(tris, dtype=np.uint32)


def plane(hx: float, hy: float) -> GeomMesh:
    """A rectangle in the z = 0 plane facing +z."""
    verts = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]], dtype=np.float32)
    return verts, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)


def _lathe(profile: np.ndarray, poles: tuple[float, float] | None = None) -> GeomMesh:
    """Revolve a (K, 2) profile of (radius, z) points about the z axis, closed at both ends by a fan
    to a point on the axis: at the end rings' heights (flat caps), or at ``poles`` (bottom, top z)."""
    angles = np.linspace(0.0, 2 * math.pi, _SEGMENTS, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (S, 2)
    verts = np.concatenate(
        [np.column_stack([ring * r, np.full(_SEGMENTS, z)]) for r, z in profile], axis=0
    )  # (K * S, 3)
    tris = []
    for k in range(len(profile) - 1):
        for s in range(_SEGMENTS):
            a, b = k * _SEGMENTS + s, k * _SEGMENTS + (s + 1) % _SEGMENTS
            c, d = a + _SEGMENTS, b + _SEGMENTS
            tris += [(a, b, d), (a, d, c)]
    last = (len(profile) - 1) * _SEGMENTS
    low, high = poles if poles is not None else (profile[0, 1], profile[-1, 1])
    caps = np.array([[0.0, 0.0, low], [0.0, 0.0, high]])
    first_cap, last_cap = len(verts), len(verts) + 1
    for s in range(_SEGMENTS):
        tris.append((first_cap, (s + 1) % _SEGMENTS, s))
        tris.append((last_cap, last + s, last + (s + 1) % _SEGMENTS))
    return np.concatenate([verts, caps]).astype(np.float32), np.asarray(tris, dtype=np.uint32)


def ellipsoid(radii: np.ndarray) -> GeomMesh:
    """An ellipsoid with semi-axes ``radii`` (3,)."""
    polar = np.linspace(math.pi, 0.0, _RINGS + 1)[1:-1]  # bottom to top, poles left to the caps
    verts, tris = _lathe(np.column_stack([np.sin(polar), np.cos(polar)]), poles=(-1.0, 1.0))
    return (verts * radii.astype(np.float32)), tris


def capsule(radius: float, half_length: float) -> GeomMesh:
    """A capsule along z: a cylinder of ``half_length`` with hemispherical ends of ``radius``."""
    polar = np.linspace(math.pi, 0.0, _RINGS + 1)[1:-1]
    r, z = np.sin(polar) * radius, np.cos(polar) * radius
    low, high = z <= 0, z >= 0
    profile = np.concatenate(
        [np.column_stack([r[low], z[low] - half_length]), np.column_stack([r[high], z[high] + half_length])]
    )
    return _lathe(profile, poles=(-half_length - radius, half_length + radius))


def cylinder(radius: float, half_length: float) -> GeomMesh:
    """A closed cylinder along z."""
    return _lathe(np.array([[radius, -half_length], [radius, half_length]]))
