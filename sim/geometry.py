"""Geometry helpers: how low a geom reaches along a direction, capsules fitted to meshes.

MuJoCo collides meshes as their convex hulls, so the lowest point of a mesh geom is the
lowest hull vertex; for primitives it follows from the size (MuJoCo XML reference, geom/size).
"""

from __future__ import annotations

import mujoco
import numpy as np

_T = mujoco.mjtGeom


def support_heights(
    model: mujoco.MjModel,
    geoms: np.ndarray,
    xpos: np.ndarray,
    xmat: np.ndarray,
    plane_point: np.ndarray,
    plane_normal: np.ndarray,
    hulls: dict[int, np.ndarray],
    cutoff: float | np.ndarray | None = None,
) -> np.ndarray:
    """Signed height of each geom's lowest point above a plane (negative = below it).

    Args:
        model: the compiled model (geom types and sizes).
        geoms: geom ids, (G,).
        xpos: geom positions, (T, G, 3).
        xmat: geom orientations, (T, G, 9) row-major.
        plane_point, plane_normal: a point on the plane and its unit normal, (T, 3) or (1, 3).
        hulls: convex-hull vertices (V, 3) in the geom frame for the mesh geoms.
        cutoff: when given (a number or one per frame, (T,)), mesh geoms whose bounding
            sphere stays above ``cutoff`` are not evaluated vertex by vertex: their entry is
            the bounding-sphere bound (a lower bound on the true height, itself above
            ``cutoff``). Exact below the cutoff.

    Returns:
        (T, G) heights in metres; NaN for geom types without a support function (plane,
        height field, SDF).
    """
    geoms = np.asarray(geoms, dtype=np.int64)
    n = np.broadcast_to(plane_normal, (xpos.shape[0], 3))
    centre = (
        np.einsum("tgk,tk->tg", xpos, n)
        - np.einsum("tk,tk->t", np.broadcast_to(plane_point, n.shape), n)[:, None]
    )
    rot = xmat.reshape(xmat.shape[0], xmat.shape[1], 3, 3)
    local_n = np.einsum("tgki,tk->tgi", rot, n)  # the normal in each geom frame, (T, G, 3)
    out = np.full(centre.shape, np.nan)
    types = model.geom_type[geoms]
    sizes = model.geom_size[geoms]
    for i, (kind, size) in enumerate(zip(types, sizes, strict=True)):
        ln = local_n[:, i]
        if kind == _T.mjGEOM_SPHERE:
            reach = np.full(ln.shape[0], size[0])
        elif kind == _T.mjGEOM_CAPSULE:
            reach = size[0] + size[1] * np.abs(ln[:, 2])
        elif kind == _T.mjGEOM_CYLINDER:
            reach = size[1] * np.abs(ln[:, 2]) + size[0] * np.sqrt(np.clip(1.0 - ln[:, 2] ** 2, 0.0, 1.0))
        elif kind == _T.mjGEOM_BOX:
            reach = np.abs(ln) @ size
        elif kind == _T.mjGEOM_ELLIPSOID:
            reach = np.sqrt(((ln * size) ** 2).sum(axis=1))
        elif kind == _T.mjGEOM_MESH and int(geoms[i]) in hulls:
            reach = np.full(ln.shape[0], float(model.geom_rbound[geoms[i]]))
            near = (
                slice(None) if cutoff is None else centre[:, i] - reach < np.broadcast_to(cutoff, reach.shape)
            )
            reach[near] = np.max(-(ln[near] @ hulls[int(geoms[i])].T), axis=1)
        else:
            continue
        out[:, i] = centre[:, i] - reach
    return out


def fit_capsule(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
    """A capsule that approximates a convex point set, along its longest principal axis.

    The axis runs through the centroid along the direction of largest spread; the radius is
    the median radial distance of the hull points from the axis (so thin protrusions and
    concave pockets of the hull do not inflate it) and the half-length covers the points'
    extent along the axis minus the radius.

    Args:
        vertices: (V, 3) points in the geom frame.

    Returns:
        (centre (3,), axis (3,) unit, radius, half_length) in the geom frame.
    """
    centre = vertices.mean(axis=0)
    spread = vertices - centre
    _, _, vt = np.linalg.svd(spread, full_matrices=False)
    axis = vt[0]
    along = spread @ axis
    radial = np.linalg.norm(spread - np.outer(along, axis), axis=1)
    radius = float(max(np.median(radial), 1e-4))
    lo, hi = float(along.min()), float(along.max())
    mid = 0.5 * (lo + hi)
    half = max(0.5 * (hi - lo) - radius, 0.0)
    return centre + mid * axis, axis, radius, half
