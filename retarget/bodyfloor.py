"""Every body above the floor, not only the feet: support points of the robot's other bodies.

Kneeling puts a knee on the floor; a deep squat or a hand on the ground brings shins and
hands near it. The solver keeps each non-foot body's lowest collision point
``SolverConfig.body_clearance`` above the floor with one residual per body and frame (its
lowest point: weighing every vertex would weigh a body by its mesh resolution). Per body the candidate
points are the collision points (hull vertices, primitive points with their radii) that are
extreme in one of ``SUPPORT_DIRECTIONS`` directions, and a body is only evaluated in the
frames where its bounding sphere reaches down to the floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.geoms import FloorPoints, collision_geoms, geom_points
from retarget.kinematics import KinematicTree, Poses

SUPPORT_DIRECTIONS = 96
"""Directions sampled for a body's support points (its lowest point is found within a few mm)."""


@dataclass(frozen=True)
class BodyFloor:
    """Support points of B bodies, grouped per body.

    Attributes:
        node: (B,) tree node of each body; points: list of (P_b, 3) in the node frame;
        radius: list of (P_b,); centre: (B, 3) and bound: (B,) a sphere enclosing each body's points.
    """

    node: np.ndarray
    points: list[np.ndarray]
    radius: list[np.ndarray]
    centre: np.ndarray
    bound: np.ndarray


def fibonacci_sphere(n: int) -> np.ndarray:
    """n roughly uniform unit vectors (n, 3)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def build_body_floor(
    model: mujoco.MjModel, tree: KinematicTree, feet: dict[str, FloorPoints]
) -> BodyFloor | None:
    """The :class:`BodyFloor` of a robot's bodies but its ``feet`` (None: the feet are all)."""
    m = model
    feet_bodies = {int(tree.node_body[f.node]) for f in feet.values()}
    dirs = fibonacci_sphere(SUPPORT_DIRECTIONS)
    node, pts, rad, centre, bound = [], [], [], [], []
    for b in range(1, m.nbody):
        if m.body_rootid[b] != tree.root_body or b in feet_bodies:
            continue
        got = [geom_points(m, g) for g in collision_geoms(m, b)]
        if not got or sum(len(p) for p, _ in got) == 0:
            continue
        bp = np.concatenate([p for p, _ in got])
        br = np.concatenate([r for _, r in got])
        keep = np.unique(np.argmax(bp @ dirs.T + br[:, None], axis=0))
        bp, br = bp[keep], br[keep]
        c = 0.5 * (bp.min(axis=0) + bp.max(axis=0))
        node.append(tree.node_of_body(b))
        pts.append(bp)
        rad.append(br)
        centre.append(c)
        bound.append(float(np.max(np.linalg.norm(bp - c, axis=1) + br)))
    if not node:
        return None
    return BodyFloor(np.array(node), pts, rad, np.array(centre), np.array(bound))


def lowest_points(poses: Poses, bf: BodyFloor, below: float) -> tuple[np.ndarray, np.ndarray]:
    """Height (T, B) of each body's lowest support point and that point (T, B, 3), world frame.

    Bodies whose bounding sphere stays above ``below`` in a frame are not evaluated there:
    their height is reported as +inf (they cannot be closer to the floor than ``below``).
    """
    t_len, b_len = poses.pos.shape[0], len(bf.node)
    low = np.full((t_len, b_len), np.inf)
    point = np.zeros((t_len, b_len, 3))
    rot = poses.rot[:, bf.node]  # (T, B, 3, 3)
    pos = poses.pos[:, bf.node]
    centre_z = pos[..., 2] + np.einsum("tbj,bj->tb", rot[..., 2, :], bf.centre)
    near = centre_z - bf.bound < below
    for b in np.flatnonzero(near.any(axis=0)):
        fr = np.flatnonzero(near[:, b])
        world = pos[fr, b, None, :] + np.einsum("fij,pj->fpi", rot[fr, b], bf.points[b])  # (F, P, 3)
        z = world[..., 2] - bf.radius[b]
        i = np.argmin(z, axis=1)
        low[fr, b] = z[np.arange(len(fr)), i]
        point[fr, b] = world[np.arange(len(fr)), i]
    return low, point
