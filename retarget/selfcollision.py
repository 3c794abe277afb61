"""Self-clearance of the arms and legs: capsule proxies of the robot's own collision geometry.

A humanoid's proportions differ from the scaled human's: G1's hips are 23 cm apart against
the scaled human's 9 cm, so arms that hang beside the human's thighs pass through the
robot's hip links; in squats and crouches the forearms sink into the thighs. The solver
keeps the arms clear with a penalty on the distance between capsules that enclose the
robot's collision geoms (:class:`SelfClearance`):

* every collision geom of the robot gets one capsule in its body's frame that encloses it
  (spheres and capsules exactly; boxes, cylinders, ellipsoids and meshes by their points:
  the axis along the points' principal direction, the radius the largest distance from it,
  the segment as short as that radius allows);
* the *arm* geoms (the bodies from below the shoulder keypoint's body down to the wrist
  keypoint's body and its descendants) are paired with every geom of the other bodies
  (trunk, legs, the other arm) except the arm's own shoulder chain and the feet (the foot
  and ankle bodies: out of reach but for touching the toes); each pair keeps
  ``SELF_MARGIN`` free, or, when its enclosures are closer than that in the (collision free)
  rest pose, comes at most ``REST_SLACK`` closer than there;
* the left leg's geoms (above the foot) are paired with the right leg's (crossing steps,
  hips turned out), with the same margins.

The solver adds, per frame and active pair, the residual ``sqrt(W_SELF) * (d - margin)``
where ``d`` is the capsules' signed distance (:func:`capsule_distances`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.kinematics import Poses, quat_to_mat

SELF_MARGIN = 0.02
"""Metres between an arm capsule and any other capsule that the solver keeps free."""


REST_SLACK = 0.005
"""A pair closer than the margin in the rest pose may come this much closer than there."""


@dataclass(frozen=True)
class SelfClearance:
    """Capsules (C) in node frames and the pairs (P) kept apart.

    Attributes:
        node: (C,) tree node (body frame) of each capsule.
        p0, p1: (C, 3) segment end points in the node frame; radius: (C,).
        first, second: (P,) capsule indices (first: the arm's).
        geom: (C,) MuJoCo geom id each capsule encloses.
        margin: (P,) distance kept free per pair: ``SELF_MARGIN``, or less for pairs whose
            capsules are closer in the rest pose (their enclosures overlap by construction).
    """

    node: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    first: np.ndarray
    second: np.ndarray
    geom: np.ndarray
    margin: np.ndarray

    @property
    def bound(self) -> np.ndarray:
        """(C,) radius of a sphere around each capsule's segment midpoint that encloses it."""
        return 0.5 * np.linalg.norm(self.p1 - self.p0, axis=1) + self.radius

    @functools.cached_property
    def mid(self) -> np.ndarray:
        """(C, 3) segment midpoints in the node frames."""
        return 0.5 * (self.p0 + self.p1)

    @functools.cached_property
    def segment(self) -> np.ndarray:
        """(C, 3) segment vectors p1 - p0 in the node frames."""
        return self.p1 - self.p0

    @functools.cached_property
    def reach_squared(self) -> np.ndarray:
        """(P,) squared distance of the bounding-sphere centres below which a pair may be
        within its margin (broad phase of :func:`close_pairs`)."""
        bound = self.bound
        return (bound[self.first] + bound[self.second] + self.margin) ** 2

    @property
    def num_pairs(self) -> int:
        return int(self.first.size)


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


def _geom_balls(model: mujoco.MjModel, g: int) -> tuple[np.ndarray, np.ndarray]:
    from retarget.robot_model import _geom_points

    if int(model.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID):  # its bounding box corners
        size = model.geom_size[g]
        sgn = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
        return model.geom_pos[g] + (sgn * size) @ quat_to_mat(model.geom_quat[g]).T, np.zeros(8)
    return _geom_points(model, g)


def _segment_distance(
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
    t = np.where(e > eps, (b * s + f) / np.maximum(e, eps), 0.0)
    t_c = np.clip(t, 0.0, 1.0)  # t outside [0, 1]: clamp it and recompute s
    s = np.where(t != t_c, np.where(a > eps, np.clip((b * t_c - c) / np.maximum(a, eps), 0.0, 1.0), 0.0), s)
    pa = p + s[..., None] * d1
    pb = q + t_c[..., None] * d2
    gap = pa - pb
    return np.sqrt(dot(gap, gap)), pa, pb


def capsule_distances(poses: Poses, sc: SelfClearance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances (T, P) of every pair and the closest axis points (T, P, 3) on each."""
    rot, pos = poses.rot[:, sc.node], poses.pos[:, sc.node]
    a0 = pos + np.einsum("tcij,cj->tci", rot, sc.p0)
    a1 = pos + np.einsum("tcij,cj->tci", rot, sc.p1)
    axis, pa, pb = _segment_distance(
        a0[:, sc.first],
        a1[:, sc.first] - a0[:, sc.first],
        a0[:, sc.second],
        a1[:, sc.second] - a0[:, sc.second],
    )
    return axis - sc.radius[sc.first] - sc.radius[sc.second], pa, pb


@dataclass
class ClosePairs:
    """Pair entries (E) closer than their margin: frame, pair index, signed distance, closest
    axis points on the first and second capsule (E, 3)."""

    frame: np.ndarray
    pair: np.ndarray
    dist: np.ndarray
    pa: np.ndarray
    pb: np.ndarray


def close_pairs(poses: Poses, sc: SelfClearance) -> ClosePairs:
    """The (frame, pair) entries closer than their margin.

    Broad phase: a sphere around each capsule (segment midpoint, half length + radius);
    only entries whose spheres come within the margin get the segment distance.
    """
    rot, pos = poses.rot[:, sc.node], poses.pos[:, sc.node]
    mid = pos + np.einsum("tcij,cj->tci", rot, sc.mid)
    diff = mid[:, sc.first] - mid[:, sc.second]
    fr, pr = np.nonzero(np.einsum("tpk,tpk->tp", diff, diff) < sc.reach_squared)
    i, j = sc.first[pr], sc.second[pr]

    def ends(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, o = rot[fr, c], pos[fr, c]
        return o + np.einsum("eij,ej->ei", r, sc.p0[c]), np.einsum("eij,ej->ei", r, sc.segment[c])

    a0, da = ends(i)
    b0, db = ends(j)
    axis, pa, pb = _segment_distance(a0, da, b0, db)
    dist = axis - sc.radius[i] - sc.radius[j]
    keep = dist < sc.margin[pr]
    return ClosePairs(fr[keep], pr[keep], dist[keep], pa[keep], pb[keep])


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


def robot_capsules(robot) -> Capsules:
    """Enclosing capsules of every collision geom of a :class:`~retarget.robot_model.RobotModel`."""
    from retarget.robot_model import collision_geoms

    m, tree = robot.model, robot.tree
    node, p0, p1, radius, geom, body = [], [], [], [], [], []
    for b in range(1, m.nbody):
        if m.body_rootid[b] != tree.root_body:
            continue
        for g in collision_geoms(m, b):
            pts, rad = _geom_balls(m, g)
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


def build_self_clearance(robot) -> SelfClearance | None:
    """Capsules and arm pairs of a :class:`~retarget.robot_model.RobotModel` (None: no arms mapped)."""

    m, tree = robot.model, robot.tree
    names = robot.keypoint_names
    parent = m.body_parentid

    def ancestors(b: int) -> list[int]:
        out = []
        while b > 0:
            out.append(b)
            b = int(parent[b])
        return out

    arm: dict[int, int] = {}  # body -> side (0 left, 1 right)
    trunk: set[int] | None = None  # ancestors shared by both arms (torso, waist, pelvis)
    for side_i, side in enumerate(("left", "right")):
        if f"{side}_wrist" not in names or f"{side}_shoulder" not in names:
            continue
        wrist = int(tree.node_body[robot.nodes[names.index(f"{side}_wrist")]])
        shoulder = int(tree.node_body[robot.nodes[names.index(f"{side}_shoulder")]])
        chain = ancestors(wrist)
        if shoulder not in chain:
            continue
        for b in chain[: chain.index(shoulder)]:
            arm[b] = side_i
        above = set(chain[chain.index(shoulder) + 1 :])
        trunk = above if trunk is None else trunk & above
        for b in range(1, m.nbody):  # the wrist body's descendants (hands)
            if wrist in ancestors(b):
                arm[b] = side_i
    # Legs: the bodies from below the trunk down to each foot (the feet themselves are left
    # to the foot locks: a stance foot is placed where the human's was).
    leg: dict[int, int] = {}
    for side_i, side in enumerate(("left", "right")):
        ankle = int(tree.node_body[robot.feet[side].node])
        for b in ancestors(ankle)[1:]:
            leg[b] = side_i
    shared = set(ancestors(int(tree.node_body[robot.feet["left"].node]))) & set(
        ancestors(int(tree.node_body[robot.feet["right"].node]))
    )
    leg = {b: s_ for b, s_ in leg.items() if b not in shared}
    if not arm and not leg:
        return None
    caps = robot.capsules
    # The feet (ankle bodies and below) are out of the arms' reach but for touching the toes.
    feet = set()
    for side in ("left", "right"):
        fb = int(tree.node_body[robot.feet[side].node])
        feet |= {b for b in range(1, m.nbody) if fb in ancestors(b) or int(parent[fb]) == b}
    node, p0, p1, radius, geom, body_of = (
        caps.node,
        caps.p0,
        caps.p1,
        caps.radius,
        caps.geom,
        caps.body.tolist(),
    )
    first, second = [], []
    for i, bi in enumerate(body_of):
        if bi not in arm:
            continue
        skip = (set(ancestors(bi)) - (trunk or set())) | feet  # the arm's own chain (the trunk is fair game)
        for j, bj in enumerate(body_of):
            if bj in skip or bi in ancestors(bj):
                continue
            if bj in arm and (arm[bj] == arm[bi] or j < i):
                continue  # same arm, or an arm-arm pair already listed
            first.append(i)
            second.append(j)
    for i, bi in enumerate(body_of):  # left leg against right leg (crossing steps, turned-out hips)
        if leg.get(bi) != 0:
            continue
        for j, bj in enumerate(body_of):
            if leg.get(bj) == 1:
                first.append(i)
                second.append(j)
    if not first:
        return None
    sc = SelfClearance(
        np.array(node),
        np.array(p0),
        np.array(p1),
        np.array(radius),
        np.array(first),
        np.array(second),
        np.array(geom),
        np.zeros(len(first)),
    )
    rest, _, _ = capsule_distances(robot.rest, sc)
    # The rest pose is collision free: pairs closer than the margin there may come that close.
    margin = np.minimum(SELF_MARGIN, rest[0] - REST_SLACK)
    return SelfClearance(sc.node, sc.p0, sc.p1, sc.radius, sc.first, sc.second, sc.geom, margin)


def clearance_normal_equations(
    tree, poses: Poses, sc: SelfClearance, close: ClosePairs, weight: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Newton rows of ``weight * (d - margin)^2`` for the close entries.

    Returns (frames (E,), Jacobian rows (E, n) scaled by sqrt(weight), residuals (E,) scaled
    by sqrt(weight)): d(d)/dx = u . (J(pa) - J(pb)), u the unit vector from pb to pa.
    """
    u = close.pa - close.pb
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    u = np.where(norm > 1e-9, u / np.maximum(norm, 1e-9), np.array([0.0, 0.0, 1.0]))
    ja = tree.directional_jacobian(poses, close.frame, sc.node[sc.first[close.pair]], close.pa, u)
    jb = tree.directional_jacobian(poses, close.frame, sc.node[sc.second[close.pair]], close.pb, u)
    root = np.sqrt(weight)
    return close.frame, root * (ja - jb), root * (close.dist - sc.margin[close.pair])
