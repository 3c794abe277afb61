"""Triangle-mesh tables the mesh SDF needs, and the closed mesh of a MuJoCo height field.

Per triangle: the pseudonormals of its seven features (:func:`pseudonormals`, for the sign),
the triangles across its edges (:func:`edge_neighbour_table`) and the ring of triangles that
share a vertex with it (:func:`ring_table`, for the nearest-triangle search of
:mod:`scenes.sdf.mesh`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # trimesh (about 1 s to import) loads only with a mesh scene: closed_mesh imports it
    import trimesh

FAN_MAX = 16
"""Triangles kept per vertex fan in the neighbour rings (see :func:`ring_table`)."""

RING_MAX = 32
"""Triangles per neighbour ring (the triangle, its edge neighbours, then vertex neighbours)."""


def pseudonormals(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per triangle, the pseudonormals of its 7 features (F, 7, 3), ordered as the feature codes:
    vertices a, b, c (angle-weighted), edges ab, bc, ca (sum of both faces), face."""
    fn = np.asarray(mesh.face_normals, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    vn = np.zeros((len(mesh.vertices), 3))
    np.add.at(vn, faces.reshape(-1), (mesh.face_angles[..., None] * fn[:, None, :]).reshape(-1, 3))
    edge_ids = np.asarray(mesh.faces_unique_edges)  # (F, 3): edges (v0,v1), (v1,v2), (v2,v0)
    en = np.zeros((len(mesh.edges_unique), 3))
    np.add.at(en, edge_ids.reshape(-1), np.repeat(fn, 3, axis=0))
    out = np.concatenate([vn[faces], en[edge_ids], fn[:, None, :]], axis=1)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    return out / np.where(norm > 0, norm, 1.0)


def edge_neighbour_table(mesh: trimesh.Trimesh) -> np.ndarray:
    """(F, 4) each triangle followed by the triangles across its three edges."""
    edge_ids = np.asarray(mesh.faces_unique_edges)  # (F, 3)
    owners = np.full((len(mesh.edges_unique), 2), -1, dtype=np.int64)
    flat_e, flat_f = edge_ids.reshape(-1), np.repeat(np.arange(len(edge_ids)), 3)
    order = np.argsort(flat_e, kind="stable")
    e_sorted, f_sorted = flat_e[order], flat_f[order]
    first = np.r_[True, e_sorted[1:] != e_sorted[:-1]]
    owners[e_sorted[first], 0] = f_sorted[first]
    owners[e_sorted[~first], 1] = f_sorted[~first]
    faces = np.arange(len(edge_ids))[:, None]
    across = np.where(owners[edge_ids, 0] == faces, owners[edge_ids, 1], owners[edge_ids, 0])
    across = np.where(across < 0, faces, across)
    return np.concatenate([faces, across], axis=1)


def ring_table(mesh: trimesh.Trimesh, edge_ring: np.ndarray) -> np.ndarray:
    """(F, K) each triangle, the triangles across its edges, then the other triangles sharing a
    vertex with it; no repeats (rows padded with the triangle itself). At most ``FAN_MAX``
    triangles per vertex fan and ``RING_MAX`` per row are kept (only vertices of unusually
    high degree lose some)."""
    faces = np.asarray(mesh.faces)
    own = np.arange(len(faces))[:, None]
    fans = np.asarray(mesh.vertex_faces)[:, :FAN_MAX]  # (V, <= FAN_MAX) padded with -1
    ring = np.concatenate([edge_ring, fans[faces].reshape(len(faces), -1)], axis=1)
    ring = np.where(ring < 0, own, ring)
    order = np.argsort(ring, axis=1, kind="stable")  # equal ids keep their order: first one wins
    sorted_ids = np.take_along_axis(ring, order, axis=1)
    repeat_sorted = np.zeros(ring.shape, dtype=bool)
    repeat_sorted[:, 1:] = sorted_ids[:, 1:] == sorted_ids[:, :-1]
    repeat = np.empty_like(repeat_sorted)
    np.put_along_axis(repeat, order, repeat_sorted, axis=1)
    front = np.argsort(repeat, axis=1, kind="stable")  # first occurrences first, in their order
    ring = np.take_along_axis(ring, front, axis=1)
    width = min(RING_MAX, int((~repeat).sum(axis=1).max()))
    keep = np.take_along_axis(~repeat, front, axis=1)[:, :width]
    return np.where(keep, ring[:, :width], own)


def heightfield_mesh(
    size: np.ndarray, nrow: int, ncol: int, data: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangle mesh (vertices, faces) of a MuJoCo height field in its geom frame.

    MuJoCo's height field spans x in [-size[0], size[0]] (columns), y in [-size[1], size[1]]
    (rows), top surface z = size[2] * data[row, col] (data in [0, 1]) and a flat base at
    z = -size[3]; each grid square is split into two triangles along the same diagonal as
    MuJoCo's height-field prisms. Returns float64 (V, 3) and int64 (F, 3) with outward winding.
    """
    rx, ry, top, base = (float(v) for v in size)
    heights = np.asarray(data, dtype=np.float64).reshape(nrow, ncol) * top
    xs = np.linspace(-rx, rx, ncol)
    ys = np.linspace(-ry, ry, nrow)
    gx, gy = np.meshgrid(xs, ys)  # (nrow, ncol)
    top_v = np.stack([gx, gy, heights], -1).reshape(-1, 3)
    vid = np.arange(nrow * ncol).reshape(nrow, ncol)
    a, b = vid[:-1, :-1].ravel(), vid[:-1, 1:].ravel()  # (r, c), (r, c+1)
    c, d = vid[1:, :-1].ravel(), vid[1:, 1:].ravel()  # (r+1, c), (r+1, c+1)
    faces = [np.stack([a, b, d], 1), np.stack([a, d, c], 1)]  # counter-clockwise seen from +z
    # The base: the same grid at z = -base, facing -z (no high-degree fan vertex).
    n_top = len(top_v)
    base_v = top_v.copy()
    base_v[:, 2] = -base
    faces += [np.stack([a, d, b], 1) + n_top, np.stack([a, c, d], 1) + n_top]
    # Walls along the boundary loop of the grid (counter-clockwise seen from +z), outward.
    ring = np.concatenate([vid[0, :], vid[1:, -1], vid[-1, -2::-1], vid[-2:0:-1, 0]])
    nxt = np.roll(ring, -1)
    faces.append(np.stack([ring, ring + n_top, nxt + n_top], 1))
    faces.append(np.stack([ring, nxt + n_top, nxt], 1))
    vertices = np.concatenate([top_v, base_v])
    return vertices, np.concatenate(faces).astype(np.int64)
