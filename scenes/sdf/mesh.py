"""Signed distance to a closed triangle mesh: exact point-triangle distances, grid-selected.

:class:`MeshSDF` answers ``sdf(points)`` for points in the mesh's own frame (metres):

* **distance**: the exact Euclidean distance to the nearest of a few candidate triangles. A
  regular grid of nodes (``pitch`` apart) covers the mesh's bounding box grown by ``pad``;
  every node stores its nearest triangle (found once, at build time, from a k-d tree of dense
  surface samples and an exact test of the sampled triangle's neighbours). A query tests the
  nearest triangles of the 8 nodes around it, then the triangles across the edges of the best
  one. This is exact whenever the point's nearest triangle is among those (nearly always);
  otherwise the triangle found is near it and the error is small (the benchmark in ``docs/BENCHMARKS.md`` measures it against
  trimesh's exact distance).
* **sign**: negative inside, from the angle-weighted pseudonormal of the feature (face, edge or
  vertex) that holds the closest point (Baerentzen & Aanaes 2005); exact for a closed,
  consistently oriented mesh.
* **gradient**: autograd of ||p - q|| with the closest point q held fixed, which is the exact
  SDF gradient (p - q is normal to the surface at q).
* **beyond the grid** (farther than ``pad`` from the bounding box) the candidates are those of
  the nearest boundary cell: still an exact distance to a real triangle (an upper bound), whose
  error grows slowly with the distance. ``pad`` (default 0.6 m) is larger than the safe
  distances the losses use, so losses never depend on it.

A mesh that is not closed (not watertight or inconsistently wound) has no inside; such a mesh
is replaced by its convex hull, which is what MuJoCo collides with anyway
(:func:`cached_mesh_sdf` warns). ``convex_hull=True`` asks for the hull for any mesh (the
simulator's view; see ``docs/scenes.md``).
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from scipy.ndimage import distance_transform_edt

from scenes.sdf.triangles import closest_point_on_triangle

Tensor = torch.Tensor

DEFAULT_PAD = 0.6
"""Metres around the mesh bounds covered by the node grid (see module docstring)."""

DEFAULT_PITCH = 0.03
"""Node spacing of the candidate grid (m)."""

MAX_NODES = 4_000_000
"""The pitch grows when a fine grid would need more nodes than this (large height fields)."""

_CHUNK = 1_000_000


@dataclass(frozen=True)
class _Grid:
    lo: np.ndarray  # (3,) first node
    pitch: float  # node spacing (m)
    shape: tuple[int, int, int]  # nodes per axis
    nearest: np.ndarray  # (nx, ny, nz) int32 nearest triangle of each node


def closed_mesh(vertices: np.ndarray, faces: np.ndarray, convex_hull: bool = False) -> tuple[trimesh.Trimesh, bool]:
    """A closed, outward-oriented trimesh of the given triangles, and whether it is their hull.

    Duplicate vertices are merged and degenerate faces dropped. When the result is not
    watertight with consistent winding (no inside exists) or ``convex_hull`` is asked, the
    convex hull is returned instead.
    """
    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64),
                           process=True, validate=False)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    if convex_hull or len(mesh.faces) < 4 or not (mesh.is_watertight and mesh.is_winding_consistent):
        return mesh.convex_hull, True
    if mesh.volume < 0:
        mesh.invert()
    return mesh, False


class MeshSDF:
    """Signed distance to a closed triangle mesh (see the module docstring).

    Args:
        mesh: a closed (watertight, consistently wound) trimesh with outward normals.
        pad: metres around the mesh bounds covered by the node grid.
        pitch: node spacing (m); raised if the grid would exceed ``MAX_NODES`` nodes.
    """

    def __init__(self, mesh: trimesh.Trimesh, pad: float = DEFAULT_PAD, pitch: float = DEFAULT_PITCH) -> None:
        self.vertices = np.asarray(mesh.vertices, dtype=np.float64)
        self.faces = np.asarray(mesh.faces, dtype=np.int64)
        self.triangles = self.vertices[self.faces]  # (F, 3, 3)
        self.normals = _pseudonormals(mesh)  # (F, 7, 3)
        self.edge_ring = _edge_neighbour_table(mesh)  # (F, 4)
        self.grid = _build_grid(mesh, self.triangles, pad=pad, pitch=pitch)
        self.is_hull = False
        self._cache: dict[tuple[torch.dtype, torch.device], dict[str, Tensor]] = {}

    @property
    def num_triangles(self) -> int:
        return len(self.faces)

    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner of the mesh (local frame)."""
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    def _tensors(self, like: Tensor) -> dict[str, Tensor]:
        key = (like.dtype, like.device)
        if key not in self._cache:
            g = self.grid
            to = dict(dtype=like.dtype, device=like.device)
            self._cache[key] = {
                "tri": torch.as_tensor(self.triangles, **to),
                "normals": torch.as_tensor(self.normals, **to),
                "lo": torch.as_tensor(g.lo, **to),
                "hi": torch.as_tensor(g.lo + g.pitch * (np.asarray(g.shape) - 1), **to),
                "shape": torch.as_tensor(g.shape, device=like.device),
                "nearest": torch.as_tensor(g.nearest.astype(np.int64), device=like.device).reshape(-1),
                "edge_ring": torch.as_tensor(self.edge_ring, device=like.device),
            }
        return self._cache[key]

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre (3,) and radius of a sphere holding the mesh (local frame, metres)."""
        centre = self.bounds().mean(0)
        return centre, float(np.linalg.norm(self.vertices - centre, axis=1).max())

    def __call__(self, points: Tensor) -> Tensor:
        """Signed distances (...,) of local points (..., 3); differentiable in ``points``."""
        shape = points.shape[:-1]
        flat = points.reshape(-1, 3)
        q, sign = self.closest(flat)
        return (sign * torch.linalg.vector_norm(flat - q, dim=-1)).reshape(shape)

    @torch.no_grad()
    def closest(self, points: Tensor) -> tuple[Tensor, Tensor]:
        """Closest mesh point (M, 3) and side (M,) (-1 inside, +1 outside) of local points (M, 3),
        without gradient: the signed distance is ``side * ||p - q||`` and its gradient that of
        ``||p - q||`` with q held fixed."""
        p = points.detach()
        return self._closest(p, self._tensors(p))

    @torch.no_grad()
    def _closest(self, p: Tensor, t: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        """Closest mesh point (M, 3) and inside/outside sign (M,); points beyond the grid box
        take the candidates of the nearest cell."""
        n = t["shape"]
        cell = ((p - t["lo"]) / self.grid.pitch).floor().long()
        cell = torch.minimum(cell.clamp_min(0), n - 2)
        corners = torch.tensor([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], device=p.device)
        node = cell[:, None, :] + corners  # (M, 8, 3)
        flat_node = (node[..., 0] * n[1] + node[..., 1]) * n[2] + node[..., 2]
        cand = t["nearest"][flat_node]  # (M, 8)
        q_best, tri_best, feat_best = _nearest_of(p, cand, t["tri"])
        # A triangle nearest to none of the 8 nodes can still be nearest to p; it is then next to
        # the best one found: test the triangles across its edges too.
        q_best, tri_best, feat_best = _nearest_of(p, t["edge_ring"][tri_best], t["tri"])
        normal = t["normals"][tri_best, feat_best]
        side = ((p - q_best) * normal).sum(-1)
        return q_best, torch.where(side < 0, -torch.ones_like(side), torch.ones_like(side))


def _nearest_of(p: Tensor, cand: Tensor, tris: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Among candidate triangles cand (M, K) of points p (M, 3): closest point, triangle, feature."""
    tri = tris[cand]  # (M, K, 3, 3)
    q, feature = closest_point_on_triangle(p[:, None, :], tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
    best = ((p[:, None, :] - q) ** 2).sum(-1).argmin(dim=1, keepdim=True)  # (M, 1)
    q_best = q.gather(1, best[..., None].expand(-1, 1, 3))[:, 0]
    return q_best, cand.gather(1, best)[:, 0], feature.gather(1, best)[:, 0]


def _pseudonormals(mesh: trimesh.Trimesh) -> np.ndarray:
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


def _surface_samples(triangles: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on every triangle (a barycentric lattice no coarser than ``spacing``) and their
    triangle ids."""
    edges = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=-1).max(-1)
    k = np.clip(np.ceil(edges / spacing).astype(int), 1, 64)
    points, owners = [], []
    for kk in np.unique(k):
        ids = np.nonzero(k == kk)[0]
        i, j = np.meshgrid(np.arange(kk + 1), np.arange(kk + 1), indexing="ij")
        keep = (i + j) <= kk
        v, w = i[keep] / kk, j[keep] / kk  # (S,)
        tri = triangles[ids]  # (n, 3, 3)
        pts = tri[:, None, 0] + v[None, :, None] * (tri[:, None, 1] - tri[:, None, 0]) \
            + w[None, :, None] * (tri[:, None, 2] - tri[:, None, 0])
        points.append(pts.reshape(-1, 3))
        owners.append(np.repeat(ids, len(v)))
    return np.concatenate(points), np.concatenate(owners)


def _neighbour_table(mesh: trimesh.Trimesh) -> np.ndarray:
    """(F, K) each triangle followed by the triangles sharing a vertex with it (padded by repeats)."""
    faces = np.asarray(mesh.faces)
    vf = mesh.vertex_faces  # (V, maxdeg) padded with -1
    ring = vf[faces].reshape(len(faces), -1)  # (F, 3 * maxdeg)
    ring = np.where(ring < 0, np.arange(len(faces))[:, None], ring)
    return np.concatenate([np.arange(len(faces))[:, None], ring], axis=1)


def _edge_neighbour_table(mesh: trimesh.Trimesh) -> np.ndarray:
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


def _best_of(nodes: Tensor, ids: Tensor, cand: Tensor, tris: Tensor) -> Tensor:
    """For nodes[ids], the candidate triangle (rows of ``cand``) nearest to each, in chunks."""
    out = torch.empty(len(ids), dtype=torch.long)
    step = max(1, _CHUNK // cand.shape[1])
    for s in range(0, len(ids), step):
        c = cand[s:s + step]
        p = nodes[ids[s:s + step]][:, None, :]
        tri = tris[c]
        q, _ = closest_point_on_triangle(p, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
        best = ((p - q) ** 2).sum(-1).argmin(dim=1, keepdim=True)
        out[s:s + step] = c.gather(1, best)[:, 0]
    return out


@torch.no_grad()
def _build_grid(mesh: trimesh.Trimesh, triangles: np.ndarray, pad: float, pitch: float) -> _Grid:
    """Nearest triangle of every grid node (see the module docstring)."""
    lo = triangles.reshape(-1, 3).min(0) - pad
    hi = triangles.reshape(-1, 3).max(0) + pad
    extent = hi - lo
    pitch = max(pitch, float(np.cbrt(np.prod(extent) / MAX_NODES)))
    shape = tuple(int(v) for v in np.ceil(extent / pitch).astype(int) + 1)
    axes = [lo[i] + pitch * np.arange(shape[i]) for i in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)

    # Seed the nodes next to the surface with the triangles sampled there, give every other
    # node the triangle of its nearest seed (Euclidean distance transform), then test the
    # triangle's neighbours exactly for the nodes near the surface.
    samples, owner = _surface_samples(triangles, spacing=pitch / 2)
    cell = np.clip(np.rint((samples - lo) / pitch).astype(np.int64), 0, np.asarray(shape) - 1)
    seed_tri = np.full(shape, -1, dtype=np.int32)
    seed_tri[cell[:, 0], cell[:, 1], cell[:, 2]] = owner
    seed_dist, seed_idx = distance_transform_edt(seed_tri < 0, return_indices=True)
    nearest = seed_tri[seed_idx[0], seed_idx[1], seed_idx[2]].reshape(-1)
    # float32 is enough to pick the nearest triangle (near-ties give near-equal distances).
    tris = torch.as_tensor(triangles, dtype=torch.float32)
    nodes_t = torch.as_tensor(nodes, dtype=torch.float32)
    nearest_t = torch.as_tensor(nearest.astype(np.int64))
    # Walk every node's triangle to an edge neighbour while that is nearer (a local descent
    # over the surface; far from it the distance varies smoothly), then, near the surface,
    # test all triangles sharing a vertex with the result.
    active = torch.arange(len(nodes))
    edge_ring = torch.as_tensor(_edge_neighbour_table(mesh))
    for _ in range(32):
        new = _best_of(nodes_t, active, edge_ring[nearest_t[active]], tris)
        moved = new != nearest_t[active]
        nearest_t[active] = new
        active = active[moved]
        if len(active) == 0:
            break
    near = torch.as_tensor(np.nonzero(seed_dist.reshape(-1) <= 2.5)[0])
    vertex_ring = torch.as_tensor(_neighbour_table(mesh))
    nearest_t[near] = _best_of(nodes_t, near, vertex_ring[nearest_t[near]], tris)
    nearest = nearest_t.numpy().astype(np.int32)
    return _Grid(lo=lo, pitch=pitch, shape=shape, nearest=nearest.reshape(shape))


_MESH_CACHE: dict[str, MeshSDF] = {}


def cached_mesh_sdf(vertices: np.ndarray, faces: np.ndarray, convex_hull: bool = False,
                    pad: float = DEFAULT_PAD, pitch: float = DEFAULT_PITCH, name: str = "mesh") -> MeshSDF:
    """A :class:`MeshSDF` of the given triangles, shared per process by content.

    Warns (once per mesh) when the mesh is not closed and its convex hull is used instead.
    """
    key = hashlib.sha1(np.ascontiguousarray(vertices, dtype=np.float64).tobytes()
                       + np.ascontiguousarray(faces, dtype=np.int64).tobytes()
                       + repr((convex_hull, pad, pitch)).encode()).hexdigest()
    if key not in _MESH_CACHE:
        mesh, is_hull = closed_mesh(vertices, faces, convex_hull=convex_hull)
        if is_hull and not convex_hull:
            warnings.warn(f"mesh '{name}' is not closed (watertight, consistently wound); its SDF uses "
                          "the convex hull, as MuJoCo's collisions do", stacklevel=2)
        sdf = MeshSDF(mesh, pad=pad, pitch=pitch)
        sdf.is_hull = is_hull
        _MESH_CACHE[key] = sdf
    return _MESH_CACHE[key]


def heightfield_mesh(size: np.ndarray, nrow: int, ncol: int, data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    # Boundary loop of the top grid, counter-clockwise seen from +z.
    ring = np.concatenate([vid[0, :], vid[1:, -1], vid[-1, -2::-1], vid[-2:0:-1, 0]])
    base_v = top_v[ring].copy()
    base_v[:, 2] = -base
    n_top, n_ring = len(top_v), len(ring)
    bottom = n_top + np.arange(n_ring)
    nxt = np.roll(np.arange(n_ring), -1)
    faces.append(np.stack([ring, bottom, bottom[nxt]], 1))  # walls, outward
    faces.append(np.stack([ring, bottom[nxt], ring[nxt]], 1))
    centre = n_top + n_ring
    faces.append(np.stack([np.full(n_ring, centre), bottom[nxt], bottom], 1))  # base fan, facing -z
    vertices = np.concatenate([top_v, base_v, [[0.0, 0.0, -base]]])
    return vertices, np.concatenate(faces).astype(np.int64)
