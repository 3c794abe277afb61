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

import numpy as np
import torch
import trimesh
from scipy.spatial import cKDTree

from scenes.sdf.triangles import closest_point_on_triangle, triangle_data, triangle_sq_distance

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

FAN_MAX = 16
"""Triangles kept per vertex fan in the neighbour rings (see :func:`_ring_table`)."""

RING_MAX = 32
"""Triangles per neighbour ring (the triangle, its edge neighbours, then vertex neighbours)."""

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
        self.normals = _pseudonormals(mesh)  # (F, 7, 3)
        self.edge_ring = _edge_neighbour_table(mesh)  # (F, 4)
        self.ring = _ring_table(mesh, self.edge_ring)  # (F, K) triangles sharing a vertex
        self.grid = _build_grid(mesh, self.triangles, self.ring, pad=pad, pitch=pitch, reach=reach)
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
                "data": triangle_data(torch.as_tensor(self.triangles, **to)),
                "normals": torch.as_tensor(self.normals, **to),
                "centre": torch.as_tensor(g.centre, **to),
                "half": torch.as_tensor(g.half, **to),
                "shape": torch.as_tensor(g.shape, device=like.device),
                "nearest": torch.as_tensor(g.nearest.astype(np.int64), device=like.device).reshape(-1),
                "ring": torch.as_tensor(self.ring.T.copy(), device=like.device),  # (K, F)
                "corners": torch.tensor(
                    [[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], device=like.device
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
        pts = (
            tri[:, None, 0]
            + v[None, :, None] * (tri[:, None, 1] - tri[:, None, 0])
            + w[None, :, None] * (tri[:, None, 2] - tri[:, None, 0])
        )
        points.append(pts.reshape(-1, 3))
        owners.append(np.repeat(ids, len(v)))
    return np.concatenate(points), np.concatenate(owners)


def _ring_table(mesh: trimesh.Trimesh, edge_ring: np.ndarray) -> np.ndarray:
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
    from :func:`_ring_table`."""
    lo, hi = triangles.reshape(-1, 3).min(0), triangles.reshape(-1, 3).max(0)
    centre = (lo + hi) / 2
    half = (hi - lo) / 2 + pad
    levels = 1 + max(0, math.ceil(math.log2(float(np.max(((hi - lo) / 2 + reach) / half)))))
    pitch = max(pitch, float(np.cbrt(levels * np.prod(2 * half) / MAX_NODES)))
    shape = tuple(int(v) for v in np.ceil(2 * half / pitch).astype(int) + 1)
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
