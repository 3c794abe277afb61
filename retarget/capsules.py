"""Capsules enclosing a robot's collision geoms, and the closest points of two segments.

Every collision geom gets one capsule in its body's frame that encloses it (spheres and
capsules exactly; boxes, cylinders, ellipsoids and meshes by their points: the axis along the
points' principal direction, the radius the largest distance from it, the segment as short
as that radius allows). :mod:`retarget.selfcollision` pairs them up.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.geoms import collision_geoms, geom_points
from retarget.kinematics import KinematicTree, Poses, quat_to_mat


def enclosing_capsule(points: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """A capsule (p0, p1, radius) enclosing balls (points (N, 3), radii (N,)).

    Axis: the points' principal direction through their centroid; radius: the largest
    radial distance (plus ball radius) from it; segment: as short as that radius allows.
    """
    if len(points) == 1:
        return points[0].copy(), points[0].copy(), float(radii[0])
    centre = points.mean(axis=0)
    spread = points - centre
    _, _, vt = np.linalg.svd(spread, full_matrices=False)
    axis = vt[0]
    along = spread @ axis
    radial = np.linalg.norm(spread - np.outer(along, axis), axis=1)
    r = float(np.max(radial + radii))
    slack = np.sqrt(np.maximum((r - radii) ** 2 - radial**2, 0.0))
    hi = float(np.max(along - slack))
    lo = float(np.min(along + slack))
    if lo > hi:
        lo = hi = 0.5 * (lo + hi)
    return centre + lo * axis, centre + hi * axis, r


def geom_balls(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Balls (centres (N, 3) in the body frame, radii (N,)) a capsule enclosing geom ``g`` encloses."""
    if int(model.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID):  # its bounding box corners
        size = model.geom_size[g]
        sgn = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
        return model.geom_pos[g] + (sgn * size) @ quat_to_mat(model.geom_quat[g]).T, np.zeros(8)
    return geom_points(model, g)


def segment_distance(
    p: np.ndarray, d1: np.ndarray, q: np.ndarray, d2: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of segments p + s d1 and q + t d2 (s, t in [0, 1]), arrays (..., 3):
    (distance between the axes (...), point on the first (..., 3), on the second (..., 3))."""
    r = p - q

    def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("...k,...k->...", u, v)  # several times faster than (u * v).sum(-1)

    a, e, f, c, b = dot(d1, d1), dot(d2, d2), dot(d2, r), dot(d1, r), dot(d1, d2)
    eps = 1e-12
    denom = a * e - b * b
    s = np.where((denom > eps) & (a > eps), np.clip((b * f - c * e) / np.maximum(denom, eps), 0.0, 1.0), 0.0)
    # The second segment a point (a sphere's capsule): the first's point nearest to it.
    s = np.where((e <= eps) & (a > eps), np.clip(-c / np.maximum(a, eps), 0.0, 1.0), s)
    t = np.where(e > eps, (b * s + f) / np.maximum(e, eps), 0.0)
    t_c = np.clip(t, 0.0, 1.0)  # t outside [0, 1]: clamp it and recompute s
    s = np.where(t != t_c, np.where(a > eps, np.clip((b * t_c - c) / np.maximum(a, eps), 0.0, 1.0), 0.0), s)
    pa = p + s[..., None] * d1
    pb = q + t_c[..., None] * d2
    gap = pa - pb
    return np.sqrt(dot(gap, gap)), pa, pb


@dataclass(frozen=True)
class Capsules:
    """One capsule per robot collision geom, enclosing it: (C,) arrays, points in node frames."""

    node: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    geom: np.ndarray
    body: np.ndarray

    def select(self, mask: np.ndarray) -> Capsules:
        return Capsules(*(getattr(self, k)[mask] for k in ("node", "p0", "p1", "radius", "geom", "body")))

    def ends(self, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
        """World end points (T, C, 3) of every capsule's segment."""
        rot = poses.rot[:, self.node]
        pos = poses.pos[:, self.node]
        return pos + np.einsum("tcij,cj->tci", rot, self.p0), pos + np.einsum("tcij,cj->tci", rot, self.p1)


def robot_capsules(model: mujoco.MjModel, tree: KinematicTree) -> Capsules:
    """Enclosing capsules of every collision geom of the robot (the bodies of ``tree``'s root)."""
    m = model
    node, p0, p1, radius, geom, body = [], [], [], [], [], []
    for b in range(1, m.nbody):
        if m.body_rootid[b] != tree.root_body:
            continue
        for g in collision_geoms(m, b):
            pts, rad = geom_balls(m, g)
            if len(pts) == 0:
                continue
            c0, c1, r = enclosing_capsule(pts, rad)
            node.append(tree.node_of_body(b))
            p0.append(c0)
            p1.append(c1)
            radius.append(r)
            geom.append(g)
            body.append(b)
    return Capsules(
        np.array(node, dtype=int),
        np.array(p0).reshape(-1, 3),
        np.array(p1).reshape(-1, 3),
        np.array(radius),
        np.array(geom, dtype=int),
        np.array(body, dtype=int),
    )
