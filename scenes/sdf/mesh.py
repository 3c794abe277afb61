"""Signed distance to a closed triangle mesh: exact point-triangle distances, grid-selected.

:class:`MeshSDF` answers ``sdf(points)`` for points in the mesh's own frame (metres):

* **distance**: the exact Euclidean distance to the nearest of a few candidate triangles,
  chosen from **nested node grids**. Level 0 covers the mesh's bounding box grown by ``pad``
  with nodes ``pitch`` apart; level k covers that box scaled by 2^k about its centre with the
  same number of nodes (pitch 2^k ``pitch``), so the levels reach ``reach`` metres beyond the
  mesh with a node spacing that grows with the distance (at most ~0.2 of the distance to the
  mesh for the defaults). Every node stores its nearest triangle, found at build time: the
  owner of the nearest surface sample (a k-d tree over samples half a level's pitch apart, so
  within that distance of the best), then improved over the triangles sharing a vertex with
  it until no node changes (the sampled guess avoids the local minima a walk over the surface
  falls into in dents). A query uses the finest level holding the point, tests the nearest
  triangles of the 8 nodes around it, then all triangles sharing a vertex with the best one
  (a lean squared-distance kernel selects; the closest point is then computed exactly). The
  result is an exact distance to a real triangle and equals the true distance whenever that
  triangle is the nearest, which is nearly always: ``docs/BENCHMARKS.md`` measures the rest
  against trimesh's exact distance, near and far (max ~4e-4 m, median ~1e-14 m, out to
  4 m). Beyond ``reach`` the outermost level's boundary cells are used and the error grows
  slowly with the distance (~2 cm at 7 m from a 0.9 m rock).
* **sign**: negative inside, from the angle-weighted pseudonormal of the feature (face, edge or
  vertex) that holds the closest point (Baerentzen & Aanaes 2005); exact for a closed,
  consistently oriented mesh.
* **gradient**: autograd of ||p - q|| with the closest point q held fixed, which is the exact
  SDF gradient (p - q is normal to the surface at q).

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
from typing import TYPE_CHECKING

import numpy as np
import torch

from scenes.sdf.topology import edge_neighbour_table, pseudonormals, ring_table
from scenes.sdf.triangles import closest_point_on_triangle, triangle_data, triangle_sq_distance

if TYPE_CHECKING:
    import trimesh

Tensor = torch.Tensor

DEFAULT_PAD = 0.3
"""Metres around the mesh bounds covered by the finest node grid (see module docstring)."""

DEFAULT_PITCH = 0.03
"""Node spacing of the finest grid (m); level k has 2^k times this."""

DEFAULT_REACH = 4.0
"""Metres beyond the mesh bounds that the coarsest grid level still covers."""

MAX_NODES = 2_000_000
"""Nodes over all levels; the pitch grows when the grids would need more (large height fields)."""

MAX_SAMPLES = 2_000_000
"""Surface samples for the k-d tree; their spacing grows when a mesh would need more."""

_PAIRS = 8_192
"""Point-triangle pairs per chunk at build time: small enough to stay in cache and below torch's
parallel grain (multi-threaded small ops lose much of their time waiting on a busy machine)."""


@dataclass(frozen=True)
class _Grid:
    centre: np.ndarray  # (3,) centre of every level's box
    half: np.ndarray  # (3,) half extents of level 0 ((shape - 1) * pitch / 2)
    pitch: float  # node spacing of level 0 (m)
    shape: tuple[int, int, int]  # nodes per axis, every level
    nearest: np.ndarray  # (levels, nx, ny, nz) int32 nearest triangle of each node

    @property
    def levels(self) -> int:
        return self.nearest.shape[0]

    def nodes(self, level: int) -> np.ndarray:
        """(nx * ny * nz, 3) node positions of a level, C order."""
        scale = 2.0**level
        axes = [
            self.centre[i] - self.half[i] * scale + self.pitch * scale * np.arange(self.shape[i])
            for i in range(3)
        ]
        return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def closed_mesh(
    vertices: np.ndarray, faces: np.ndarray, convex_hull: bool = False
) -> tuple[trimesh.Trimesh, bool]:
    """A closed, outward-oriented trimesh of the given triangles, and whether it is their hull.

    Duplicate vertices are merged and degenerate faces dropped. When the result is not
    watertight with consistent winding (no inside exists) or ``convex_hull`` is asked, the
    convex hull is returned instead.
    """
    import trimesh  # heavy (about 1 s with networkx): only scenes with meshes or height fields need it

    mesh = trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64),
        np.asarray(faces, dtype=np.int64),
        process=True,
        validate=False,
    )
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
        pad: metres around the mesh bounds covered by the finest node grid.
        pitch: node spacing of the finest grid (m); raised if a level would exceed ``MAX_NODES``.
        reach: metres beyond the mesh bounds covered by the coarsest level.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        pad: float = DEFAULT_PAD,
        pitch: float = DEFAULT_PITCH,
        reach: float = DEFAULT_REACH,
    ) -> None:
        self.vertices = np.asarray(mesh.vertices, dtype=np.float64)
        self.faces = np.asarray(mesh.faces, dtype=np.int64)
        self.triangles = self.vertices[self.faces]  # (F, 3, 3)
        self.normals = pseudonormals(mesh)  # (F, 7, 3)
        self.edge_ring = edge_neighbour_table(mesh)  # (F, 4)
        self.ring = ring_table(mesh, self.edge_ring)  # (F, K) triangles sharing a vertex
        self.grid = _build_grid(mesh, self.triangles, self.ring, pad=pad, pitch=pitch, reach=reach)
        self.is_hull = False
        self._cache: dict[tuple[torch.dtype, torch.device], dict[str, Tensor]] = {}

    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner of the mesh (local frame)."""
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    def _tensors(self, like: Tensor) -> dict[str, Tensor]:
        key = (like.dtype, like.device)
        if key not in self._cache:
            g = self.grid
            dtype, device = like.dtype, like.device
            self._cache[key] = {
                "tri": torch.as_tensor(self.triangles, dtype=dtype, device=device),
                "data": triangle_data(torch.as_tensor(self.triangles, dtype=dtype, device=device)),
                "normals": torch.as_tensor(self.normals, dtype=dtype, device=device),
                "centre": torch.as_tensor(g.centre, dtype=dtype, device=device),
                "half": torch.as_tensor(g.half, dtype=dtype, device=device),
                "shape": torch.as_tensor(g.shape, device=device),
                "nearest": torch.as_tensor(g.nearest.astype(np.int64), device=device).reshape(-1),
                "ring": torch.as_tensor(self.ring.T.copy(), device=device),  # (K, F)
                "corners": torch.tensor(
                    [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], device=device
                ),
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
        """Closest mesh point (M, 3) and inside/outside sign (M,) of points p (M, 3)."""
        g, n = self.grid, t["shape"]
        # The finest level whose box holds p: level k spans centre +- half * 2^k.
        ratio = ((p - t["centre"]).abs() / t["half"]).amax(dim=-1)
        level = torch.log2(ratio.clamp_min(1e-30)).ceil_().clamp_(0, g.levels - 1)  # (M,) float
        scale = torch.exp2(level)[:, None]
        cell = ((p - t["centre"]) / (g.pitch * scale) + (n - 1) / 2).floor_().long()
        cell = torch.minimum(cell.clamp_min(0), n - 2)  # beyond the outermost level: its boundary cells
        node = cell + t["corners"][:, None, :]  # (8, M, 3)
        flat = ((level.long() * n[0] + node[..., 0]) * n[1] + node[..., 1]) * n[2] + node[..., 2]
        pt = p.T[:, None, :]  # (3, 1, M)
        best = _nearest_of(pt, torch.take(t["nearest"], flat), t["data"])  # among the 8 nodes' triangles
        # A triangle nearest to none of the 8 nodes can still be nearest to p; it then shares a
        # vertex with the best one found (nearly always): test those too.
        best = _nearest_of(pt, t["ring"].index_select(1, best), t["data"])
        tri = t["tri"].index_select(0, best)
        q_best, feature = closest_point_on_triangle(p, tri[:, 0], tri[:, 1], tri[:, 2])
        normal = t["normals"][best, feature]
        side = ((p - q_best) * normal).sum(-1)
        return q_best, torch.where(side < 0, -torch.ones_like(side), torch.ones_like(side))


def _nearest_of(pt: Tensor, cand: Tensor, data: Tensor) -> Tensor:
    """The candidate triangle (M,) nearest to each point among ``cand`` (K, M); points
    ``pt`` (3, 1, M), ``data`` (16, F) from :func:`triangle_data`."""
    rows = data.index_select(1, cand.reshape(-1)).view(data.shape[0], *cand.shape)
    d2 = triangle_sq_distance(pt, rows)  # (K, M)
    return cand.gather(0, d2.min(dim=0).indices[None])[0]


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
        pts = (
            tri[:, None, 0]
            + v[None, :, None] * (tri[:, None, 1] - tri[:, None, 0])
            + w[None, :, None] * (tri[:, None, 2] - tri[:, None, 0])
        )
        points.append(pts.reshape(-1, 3))
        owners.append(np.repeat(ids, len(v)))
    return np.concatenate(points), np.concatenate(owners)


def _best_of(nodes: Tensor, cand: Tensor, data: Tensor) -> Tensor:
    """The candidate triangle (a row of ``cand`` (N, K)) nearest to each node (N, 3), in chunks;
    ``data`` (16, F) from :func:`triangle_data`."""
    out = torch.empty(len(nodes), dtype=torch.long)
    step = max(1, _PAIRS // cand.shape[1])
    for s in range(0, len(nodes), step):
        c = cand[s : s + step]
        rows = data.index_select(1, c.reshape(-1)).view(data.shape[0], *c.shape)
        d2 = triangle_sq_distance(nodes[s : s + step].T[..., None], rows)
        out[s : s + step] = c.gather(1, d2.argmin(dim=1, keepdim=True))[:, 0]
    return out


@torch.no_grad()
def _build_grid(
    mesh: trimesh.Trimesh, triangles: np.ndarray, ring: np.ndarray, pad: float, pitch: float, reach: float
) -> _Grid:
    """Nested grids and the nearest triangle of their nodes (see the module docstring); ``ring``
    from :func:`scenes.sdf.topology.ring_table`."""
    from scipy.spatial import cKDTree  # with trimesh: only scenes with meshes build these grids

    lo, hi = triangles.reshape(-1, 3).min(0), triangles.reshape(-1, 3).max(0)
    centre = (lo + hi) / 2
    half = (hi - lo) / 2 + pad
    levels = 1 + max(0, math.ceil(math.log2(float(np.max(((hi - lo) / 2 + reach) / half)))))
    pitch = max(pitch, float(np.cbrt(levels * np.prod(2 * half) / MAX_NODES)))
    nx, ny, nz = (int(v) for v in np.ceil(2 * half / pitch).astype(int) + 1)
    shape = (nx, ny, nz)
    half = (np.asarray(shape) - 1) * pitch / 2  # >= the asked half extents, so levels still reach

    base_spacing = max(pitch / 2, math.sqrt(2 * float(mesh.area) / MAX_SAMPLES))
    data = triangle_data(
        torch.as_tensor(triangles, dtype=torch.float32)
    )  # float32 picks the nearest well enough
    vertex_ring = torch.as_tensor(ring)
    nearest = np.zeros((levels, *shape), dtype=np.int32)
    for level in range(levels):
        nodes = _Grid(centre, half, pitch, shape, nearest).nodes(level)
        need = np.ones(len(nodes), dtype=bool)
        if level > 0:  # nodes strictly inside the finer level (by one node) are never used
            inner = half * 2.0 ** (level - 1) - pitch * 2.0**level
            need = np.any(np.abs(nodes - centre) > inner, axis=1)
        # The owner of the nearest surface sample (samples half the level's pitch apart, so
        # within that of the best), then the triangles sharing a vertex with it, exactly.
        samples, owner = _surface_samples(triangles, spacing=base_spacing * 2.0**level)
        _, idx = cKDTree(samples).query(nodes[need])
        best = torch.as_tensor(owner[idx])
        points = torch.as_tensor(nodes[need], dtype=torch.float32)
        active = torch.arange(len(points))
        for _ in range(8):  # until no node moves (most settle in one round)
            new = _best_of(points[active], vertex_ring[best[active]], data)
            moved = new != best[active]
            best[active] = new
            active = active[moved]
            if len(active) == 0:
                break
        nearest[level].reshape(-1)[need] = best.numpy()
    return _Grid(centre=centre, half=half, pitch=pitch, shape=shape, nearest=nearest)


_MESH_CACHE: dict[str, MeshSDF] = {}


def cached_mesh_sdf(
    vertices: np.ndarray,
    faces: np.ndarray,
    convex_hull: bool = False,
    pad: float = DEFAULT_PAD,
    pitch: float = DEFAULT_PITCH,
    name: str = "mesh",
    reach: float = DEFAULT_REACH,
) -> MeshSDF:
    """A :class:`MeshSDF` of the given triangles, shared per process by content.

    Warns (once per mesh) when the mesh is not closed and its convex hull is used instead.
    """
    key = hashlib.sha1(
        np.ascontiguousarray(vertices, dtype=np.float64).tobytes()
        + np.ascontiguousarray(faces, dtype=np.int64).tobytes()
        + repr((convex_hull, pad, pitch, reach)).encode()
    ).hexdigest()
    if key not in _MESH_CACHE:
        mesh, is_hull = closed_mesh(vertices, faces, convex_hull=convex_hull)
        if is_hull and not convex_hull:
            warnings.warn(
                f"mesh '{name}' is not closed (watertight, consistently wound); its SDF uses "
                "the convex hull, as MuJoCo's collisions do",
                stacklevel=2,
            )
        sdf = MeshSDF(mesh, pad=pad, pitch=pitch, reach=reach)
        sdf.is_hull = is_hull
        _MESH_CACHE[key] = sdf
    return _MESH_CACHE[key]
