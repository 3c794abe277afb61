"""Closest points on triangles (the building block of exact mesh distances).

``closest_point_on_triangle`` follows the Voronoi-region case analysis of a triangle
(three vertex regions, three edge regions, the face) and also returns which feature holds
the closest point, so the caller can pick the matching angle-weighted pseudonormal for the
inside/outside sign (Baerentzen & Aanaes, "Signed distance computation using the angle
weighted pseudonormal", IEEE TVCG 2005).
"""

from __future__ import annotations

import torch

Tensor = torch.Tensor

VERTEX_A, VERTEX_B, VERTEX_C, EDGE_AB, EDGE_BC, EDGE_CA, FACE = range(7)
"""Feature codes returned by :func:`closest_point_on_triangle`."""


def _safe_div(num: Tensor, den: Tensor) -> Tensor:
    return num / torch.where(den.abs() > torch.finfo(den.dtype).tiny, den, torch.ones_like(den))


def closest_point_on_triangle(p: Tensor, a: Tensor, b: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
    """Closest point to ``p`` on triangle ``(a, b, c)``; all (..., 3), broadcast together.

    Returns:
        q: (..., 3) the closest point.
        feature: (...,) int64 code of the feature holding q (``VERTEX_A`` ... ``FACE``).
    """
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2

    # Barycentric weights (v on ab, w on ac) of the face case, then overwrite region by region
    # in reverse priority order so that the first matching region of the case analysis wins.
    den = va + vb + vc
    v, w = _safe_div(vb, den), _safe_div(vc, den)
    feature = torch.full(v.shape, FACE, dtype=torch.int64, device=v.device)
    zero, one = torch.zeros_like(v), torch.ones_like(v)

    def region(mask: Tensor, v_new: Tensor, w_new: Tensor, code: int) -> None:
        nonlocal v, w, feature
        v, w = torch.where(mask, v_new, v), torch.where(mask, w_new, w)
        feature = torch.where(mask, torch.full_like(feature, code), feature)

    e43, e56 = d4 - d3, d5 - d6
    t_bc = _safe_div(e43, e43 + e56)
    region((va <= 0) & (e43 >= 0) & (e56 >= 0), 1 - t_bc, t_bc, EDGE_BC)
    region((vb <= 0) & (d2 >= 0) & (d6 <= 0), zero, _safe_div(d2, d2 - d6), EDGE_CA)
    region((d6 >= 0) & (d5 <= d6), zero, one, VERTEX_C)
    region((vc <= 0) & (d1 >= 0) & (d3 <= 0), _safe_div(d1, d1 - d3), zero, EDGE_AB)
    region((d3 >= 0) & (d4 <= d3), one, zero, VERTEX_B)
    region((d1 <= 0) & (d2 <= 0), zero, zero, VERTEX_A)
    q = a + v[..., None] * ab + w[..., None] * ac
    return q, feature


TRIANGLE_DATA = 16
"""Rows of :func:`triangle_data`: a (3), b - a (3), c - a (3), unit normal (3), |ab|^2, ab.ac,
|ac|^2, |bc|^2."""


def triangle_data(triangles: Tensor) -> Tensor:
    """Per-triangle constants (16, F) of :func:`triangle_sq_distance` for triangles (F, 3, 3),
    one row per quantity (so that gathered rows stay contiguous)."""
    a, b, c = triangles.unbind(-2)
    ab, ac = b - a, c - a
    n = torch.linalg.cross(ab, ac)
    n = n / torch.linalg.vector_norm(n, dim=-1, keepdim=True).clamp_min(torch.finfo(n.dtype).tiny)
    d00, d01, d11 = (ab * ab).sum(-1), (ab * ac).sum(-1), (ac * ac).sum(-1)
    return torch.cat(
        [a, ab, ac, n, torch.stack([d00, d01, d11, d00 - 2 * d01 + d11], -1)], dim=-1
    ).T.contiguous()


def triangle_sq_distance(p: Tensor, data: Tensor) -> Tensor:
    """Squared distance (...,) from points to triangles: ``p`` (3, ...) point coordinates and
    ``data`` (16, ...) columns of :func:`triangle_data`, broadcast together.

    A lean form for choosing the nearest of many triangles (about 50 operations on scalars per
    pair, no closest point): the squared distance to the plane when the projection falls
    inside the triangle, else the least over the three edges, each from dot products with the
    precomputed edge vectors. Cancellation makes it less exact than
    :func:`closest_point_on_triangle` for points much farther away than the triangle is wide,
    so it selects, and that function then gives the distance.
    """
    ax, ay, az, abx, aby, abz, acx, acy, acz, nx, ny, nz, d00, d01, d11, d22 = data.unbind(0)
    x, y, z = p[0] - ax, p[1] - ay, p[2] - az  # ap
    d1 = (abx * x).addcmul_(aby, y).addcmul_(abz, z)  # ab.ap
    d2 = (acx * x).addcmul_(acy, y).addcmul_(acz, z)  # ac.ap
    h = (nx * x).addcmul_(ny, y).addcmul_(nz, z)  # height over the plane
    ap2 = (x * x).addcmul_(y, y).addcmul_(z, z)
    # barycentric coordinates of the projection, times the Gram determinant (> 0)
    v = d11 * d1 - d01 * d2
    w = d00 * d2 - d01 * d1
    inside = (v >= 0) & (w >= 0) & (v + w <= d00 * d11 - d01 * d01)
    # edges: |x - t e|^2 = |x|^2 - 2 t x.e + t^2 |e|^2 with t clamped to [0, 1]
    tiny = torch.finfo(d1.dtype).tiny
    t = (d1 / d00.clamp_min(tiny)).clamp_(0, 1)
    edge = ap2 - t * (2 * d1 - t * d00)
    t = (d2 / d11.clamp_min(tiny)).clamp_(0, 1)
    edge = torch.minimum(edge, ap2 - t * (2 * d2 - t * d11))
    bp_bc = d2 - d1 - d01 + d00  # (ap - ab).(ac - ab)
    t = (bp_bc / d22.clamp_min(tiny)).clamp_(0, 1)
    edge = torch.minimum(edge, ap2 - 2 * d1 + d00 - t * (2 * bp_bc - t * d22))
    return torch.where(inside, h * h, edge).clamp_min_(0)
