"""Self-clearance of the arms and legs: capsule proxies of the robot's own collision geometry.

A humanoid's proportions differ from the scaled human's: G1's hips are 23 cm apart against
the scaled human's 9 cm, so arms that hang beside the human's thighs pass through the
robot's hip links; in squats and crouches the forearms sink into the thighs. The solver
keeps the arms clear with a penalty on the distance between capsules that enclose the
robot's collision geoms (:class:`SelfClearance`):

* every collision geom of the robot gets one capsule in its body's frame that encloses it
  (:mod:`retarget.capsules`);
* the *arm* geoms (the bodies from below the shoulder keypoint's body down to the wrist
  keypoint's body and its descendants) are paired with every geom of the other bodies
  (trunk, legs, the other arm) except the arm's own shoulder chain and the feet (the foot
  and ankle bodies: out of reach but for touching the toes; a shin the foot hangs from
  directly is not an ankle body), and the hand (the wrist body and
  below) with that shoulder chain where the two are apart at rest (a hand brought to its own
  shoulder); each pair keeps
  ``SELF_MARGIN`` free, or, when its enclosures are closer than that in the (collision free)
  rest pose, comes at most ``REST_SLACK`` closer than there;
* within a hand, the links that branch from it (fingers against thumb, fingers side by
  side) where MuJoCo collides them, with the same margins: the arm's pairs would otherwise
  push a thumb out of a shin into the fingers;
* the left leg's geoms (feet included) are paired with the right leg's (crossing steps,
  hips turned out, feet placed close together), and in each leg the links above the knee
  with the links below the knee's own (a deep crouch), with the same margins; the knee's own
  link (the shin) against its foot below the ankle link only where their real geoms touch
  within the ankle joints' ranges (bone meshes: loco-mujoco's skeleton), calibrated by a
  sweep as the trunk's pairs below;
* the trunk (the pelvis and the bodies above it up to the shoulders) against the links above
  each knee (a deep stoop or crouch folds the trunk onto the hips), but for a parent and its
  child. Where their enclosures come closer than ``SELF_MARGIN`` in the rest pose (a pelvis
  and the hip link hanging below it) the rest pose says nothing about contact: the margin is
  calibrated on the real geoms by a sweep of the joints between them
  (:func:`swept_margins`); a pair whose geoms never touch in the sweep, or that cannot be swept
  (the trunk body not above the leg link, too many joints between them), is dropped;
* on robots with meshes, also the trunk against each arm's shoulder links (the chain from
  the trunk down to the shoulder keypoint), calibrated the same way: the first solve of
  :mod:`retarget.selfcheck` lets the arms closer to the trunk, and they roll those links
  into it;
* on robots without meshes, the trunk against the shoulder links and the trunk's own links
  that are neither parent and child (a jointed spine: the CMU humanoid's pelvis and upper
  back), and the head's links against the shoulder links (a jointed neck folding the head
  onto a clavicle), where both are capsules or spheres (exact enclosures) that MuJoCo
  collides; such pairs closer than ``SELF_MARGIN`` at rest are left out.

The solver adds, per frame and active pair, the residual ``sqrt(w_self) * (d - margin)``
where ``d`` is the capsules' signed distance (:func:`capsule_distances`;
:class:`retarget.costs.self_clearance.SelfClearanceCost`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from retarget.broad_phase import PairGroups, candidates, pair_groups
from retarget.capsules import Capsules, segment_distance
from retarget.geoms import FloorPoints, excluded_body_pairs
from retarget.kinematics import KinematicTree, Poses

SELF_MARGIN = 0.02
"""Metres between an arm capsule and any other capsule that the solver keeps free."""


TRUNK_MARGIN = 0.005
"""Metres kept between the trunk's and a thigh link's capsules (enclosures: 0 is contact free)."""


_EXACT = (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE))
"""Geom types whose enclosing capsule is the geom itself."""

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
        looseness: (P,) how loosely the pair's capsules may enclose its geoms (m): the radii of
            its capsules around meshes, summed (0: exact or close enclosures, capsules,
            cylinders, boxes; a hand against its own shoulder and the trunk-shoulder pairs 0).
        relaxed_pairs: the same with the pairs a relaxed solve keeps besides (the trunk
            against the shoulder links), or None.
        safe_margin: (P,) the margin each pair goes back to where its real geoms touch
            (:mod:`retarget.selfcheck`); ``margin`` may be smaller (a first solve that lets the
            loose enclosures overlap). None: the same as ``margin``.
        balls: how many of the capsules, the last ones, are balls held where two geoms touch
            (:meth:`with_balls`), not enclosures of a geom.
    """

    node: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    first: np.ndarray
    second: np.ndarray
    geom: np.ndarray
    margin: np.ndarray
    safe_margin: np.ndarray | None = None
    looseness: np.ndarray | None = None
    relaxed_pairs: SelfClearance | None = None
    balls: int = 0

    def relaxed(self, fraction: float, most: float) -> SelfClearance:
        """A copy in which each pair with a margin of at least 0 may come closer by
        ``fraction`` of its ``looseness``, at most ``most`` metres (pairs whose enclosures
        overlap at rest keep theirs), with the pairs of ``relaxed_pairs`` when given;
        ``safe_margin`` remembers the margins of this one."""
        base = self if self.relaxed_pairs is None else self.relaxed_pairs
        safe = base.margin if base.safe_margin is None else base.safe_margin
        loose = np.zeros_like(safe) if base.looseness is None else base.looseness
        margin = np.where(safe >= 0.0, safe - np.minimum(fraction * loose, most), base.margin)
        return replace(base, margin=margin, safe_margin=safe, relaxed_pairs=None)

    def tightened(
        self,
        depth: np.ndarray,
        tolerance: float | np.ndarray,
        gap: np.ndarray | None = None,
        keep_seen: bool = False,
    ) -> SelfClearance:
        """A copy in which the pairs whose real geoms overlap deeper than ``tolerance``
        (m, one or (P,); ``depth`` (P,), m) keep more room: their safe margin when below it, else their
        margin plus that depth (the margin is a soft penalty that other terms can overcome).
        ``gap`` (P,), m: each pair's capsule distance where its geoms overlapped deepest
        (:func:`retarget.selfcheck.overlap_gaps`); the margin is then at least that plus the
        depth. Loose enclosures that overlap at rest (a shoulder link's inside the torso's,
        5 cm) may have their geoms overlap with the capsules well outside the margin, where
        the margin plus the depth does not push them apart at all. With ``keep_seen`` the
        pairs that :meth:`seen_by_balls` names keep theirs: their balls get the room."""
        safe = self.margin if self.safe_margin is None else self.safe_margin
        bad = depth > tolerance
        if keep_seen:
            bad = bad & ~self.seen_by_balls()
        more = np.where(self.margin < safe, np.maximum(safe, self.margin + depth), self.margin + depth)
        if gap is not None:
            more = np.maximum(more, gap + depth)
        return replace(self, margin=np.where(bad, more, self.margin))

    def seen_by_balls(self) -> np.ndarray:
        """(P,) bool: the enclosure pairs that overlap at rest (a negative margin) between two
        geoms that a pair of balls also keeps apart (:meth:`with_balls`). Such enclosures do not
        see where their geoms touch, and more room for them can press the geoms together:
        Kuavo's hip cylinders, whose capsules overlap by 9 cm at rest, had their rims 6.4, 7.0
        and 7.8 mm into each other as their margin grew with the output check's rungs."""
        ball = self.first >= len(self.node) - self.balls  # the balls are the last capsules
        if not ball.any():
            return ball
        geoms = np.sort(np.stack([self.geom[self.first], self.geom[self.second]], axis=1), axis=1)
        held = {(int(a), int(b)) for a, b in geoms[ball]}
        shared = np.array([(int(a), int(b)) in held for a, b in geoms])
        return shared & ~ball & (self.margin < 0.0)

    def with_pairs(self, first: np.ndarray, second: np.ndarray, margin: float | np.ndarray) -> SelfClearance:
        """A copy keeping the capsule pairs ``first``, ``second`` (Q,) apart too, with
        ``margin`` (m, one or (Q,); no looseness), e.g. geoms found overlapping that the pairs
        built from the robot's anatomy leave alone (:func:`retarget.selfcheck.unpaired_overlaps`)."""
        extra = np.broadcast_to(np.asarray(margin, dtype=np.float64), (len(first),)).copy()

        def grow(values: np.ndarray | None, more: np.ndarray) -> np.ndarray | None:
            return None if values is None else np.concatenate([values, more])

        return replace(
            self,
            first=np.concatenate([self.first, np.asarray(first, dtype=int)]),
            second=np.concatenate([self.second, np.asarray(second, dtype=int)]),
            margin=np.concatenate([self.margin, extra]),
            safe_margin=grow(self.safe_margin, extra),
            looseness=grow(self.looseness, np.zeros(len(first))),
            relaxed_pairs=None,
        )

    def with_balls(
        self, node: np.ndarray, centre: np.ndarray, radius: np.ndarray, geom: np.ndarray, margin: float
    ) -> SelfClearance:
        """A copy with Q pairs of balls kept ``margin`` (m) apart too: ``node`` (Q, 2) the tree
        nodes they ride on, ``centre`` (Q, 2, 3) in those nodes' frames, ``radius`` (Q, 2) m,
        ``geom`` (Q, 2) the geoms they lie in (:func:`retarget.selfcheck.contact_balls`: two
        geoms whose enclosures do not see where they touch). The balls are capsules of zero
        length appended after the others; the pairs after the others too."""
        c = len(self.node)
        q = len(node)
        grown = replace(
            self,
            node=np.concatenate([self.node, np.asarray(node, dtype=int).ravel()]),
            p0=np.concatenate([self.p0, np.asarray(centre).reshape(-1, 3)]),
            p1=np.concatenate([self.p1, np.asarray(centre).reshape(-1, 3)]),
            radius=np.concatenate([self.radius, np.asarray(radius, dtype=np.float64).ravel()]),
            geom=np.concatenate([self.geom, np.asarray(geom, dtype=int).ravel()]),
            balls=self.balls + 2 * q,
        )
        index = c + np.arange(2 * q).reshape(q, 2)
        return grown.with_pairs(index[:, 0], index[:, 1], margin)

    def select_pairs(self, keep: np.ndarray) -> SelfClearance:
        """A copy with the pairs where ``keep`` (P,) bool is true (their margins and looseness)."""

        def take(values: np.ndarray | None) -> np.ndarray | None:
            return None if values is None else values[keep]

        return replace(
            self,
            first=self.first[keep],
            second=self.second[keep],
            margin=self.margin[keep],
            safe_margin=take(self.safe_margin),
            looseness=take(self.looseness),
            relaxed_pairs=None,
        )

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

    @functools.cached_property
    def groups(self) -> PairGroups | None:
        """The pairs grouped by capsule clusters (the first level of :func:`close_pairs`' broad
        phase; None where too few pairs share their clusters to gain from it)."""
        return pair_groups(
            self.node, self.mid, self.bound, self.first, self.second, np.sqrt(self.reach_squared)
        )

    def group_centres(self, poses: Poses) -> np.ndarray | None:
        """(T, N, 3) world centres of the cluster spheres of :attr:`groups` in ``poses`` (None
        without groups)."""
        g = self.groups
        if g is None:
            return None
        return poses.pos[:, g.node] + np.einsum("tnij,nj->tni", poses.rot[:, g.node], g.centre)

    @property
    def num_pairs(self) -> int:
        return int(self.first.size)


def capsule_distances(poses: Poses, sc: SelfClearance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances (T, P) of every pair and the closest axis points (T, P, 3) on each
    (only the capsules of the pairs are placed: a few pairs of a robot with 1,103 capsules)."""
    used, inverse = np.unique(np.concatenate([sc.first, sc.second]), return_inverse=True)
    i, j = inverse[: sc.num_pairs], inverse[sc.num_pairs :]
    rot, pos = poses.rot[:, sc.node[used]], poses.pos[:, sc.node[used]]
    a0 = pos + np.einsum("tcij,cj->tci", rot, sc.p0[used])
    a1 = pos + np.einsum("tcij,cj->tci", rot, sc.p1[used])
    axis, pa, pb = segment_distance(a0[:, i], a1[:, i] - a0[:, i], a0[:, j], a1[:, j] - a0[:, j])
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
    only entries whose spheres come within the margin get the segment distance, and only
    the pairs whose clusters' spheres come that close get that test (:mod:`retarget.broad_phase`).
    """
    rot, pos = poses.rot[:, sc.node], poses.pos[:, sc.node]
    mid = pos + np.einsum("tcij,cj->tci", rot, sc.mid)
    fr, pr = candidates(sc.groups, mid, sc.group_centres(poses), sc.first, sc.second, sc.reach_squared)
    i, j = sc.first[pr], sc.second[pr]

    if fr.size > mid.shape[0] * mid.shape[1]:  # more entries than capsules: every segment once
        start = pos + np.einsum("tcij,cj->tci", rot, sc.p0)
        vector = np.einsum("tcij,cj->tci", rot, sc.segment)

        def ends(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return start[fr, c], vector[fr, c]

    else:

        def ends(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            r, o = rot[fr, c], pos[fr, c]
            return o + np.einsum("eij,ej->ei", r, sc.p0[c]), np.einsum("eij,ej->ei", r, sc.segment[c])

    a0, da = ends(i)
    b0, db = ends(j)
    axis, pa, pb = segment_distance(a0, da, b0, db)
    dist = axis - sc.radius[i] - sc.radius[j]
    keep = dist < sc.margin[pr]
    return ClosePairs(fr[keep], pr[keep], dist[keep], pa[keep], pb[keep])


def _collides(m: mujoco.MjModel, g1: int, g2: int) -> bool:
    """Whether MuJoCo's contype/conaffinity filter lets geoms ``g1`` and ``g2`` collide."""
    return bool(m.geom_contype[g1] & m.geom_conaffinity[g2] or m.geom_contype[g2] & m.geom_conaffinity[g1])


def build_self_clearance(
    model: mujoco.MjModel,
    tree: KinematicTree,
    keypoint_nodes: dict[str, int],
    feet: dict[str, FloorPoints],
    capsules: Capsules,
    rest: Poses,
) -> SelfClearance | None:
    """The capsule pairs of a robot kept apart (None: no arm or leg pairs).

    Args:
        model, tree: the robot; keypoint_nodes: mapped human joint name -> tree node;
        feet: the robot's feet ("left", "right"); capsules: :func:`retarget.capsules.robot_capsules`;
        rest: the rest pose (one frame), collision free: it sets the margins of close pairs.
    """
    m = model
    parent = m.body_parentid

    def ancestors(b: int) -> list[int]:
        out = []
        while b > 0:
            out.append(b)
            b = int(parent[b])
        return out

    arm: dict[int, int] = {}  # body -> side (0 left, 1 right)
    hands: dict[int, int] = {}  # the wrist body and its descendants -> side
    shoulders: dict[int, set[int]] = {}  # side -> the shoulder body and the chain above it
    trunk: set[int] | None = None  # ancestors shared by both arms (torso, waist, pelvis)
    for side_i, side in enumerate(("left", "right")):
        if f"{side}_wrist" not in keypoint_nodes or f"{side}_shoulder" not in keypoint_nodes:
            continue
        wrist = int(tree.node_body[keypoint_nodes[f"{side}_wrist"]])
        shoulder = int(tree.node_body[keypoint_nodes[f"{side}_shoulder"]])
        chain = ancestors(wrist)
        if shoulder not in chain:
            continue
        for b in chain[: chain.index(shoulder)]:
            arm[b] = side_i
        above = set(chain[chain.index(shoulder) + 1 :])
        trunk = above if trunk is None else trunk & above
        shoulders[side_i] = set(chain[chain.index(shoulder) :])
        for b in range(1, m.nbody):  # the wrist body's descendants (hands)
            if wrist in ancestors(b):
                arm[b] = side_i
                hands[b] = side_i
    # Legs: the bodies from below the trunk down to each foot and the foot's own (toes):
    # the feet follow the human's, which may stand closer together than the robot's allow.
    leg: dict[int, int] = {}
    for side_i, side in enumerate(("left", "right")):
        ankle = int(tree.node_body[feet[side].node])
        for b in ancestors(ankle):
            leg[b] = side_i
        for b in range(1, m.nbody):
            if ankle in ancestors(b):
                leg[b] = side_i
    shared = set(ancestors(int(tree.node_body[feet["left"].node]))) & set(
        ancestors(int(tree.node_body[feet["right"].node]))
    )
    leg = {b: s_ for b, s_ in leg.items() if b not in shared}
    if not arm and not leg:
        return None
    caps = capsules
    # The feet (ankle bodies and below) are out of the arms' reach but for touching the toes.
    # The ankle link above the foot too, unless it is the shin (the knee's body: MuJoCo's,
    # the CMU and SMPL humanoids' and H1's feet hang from the shin, which a stooping hand reaches).
    foot_bodies: set[int] = set()
    for side in ("left", "right"):
        fb = int(tree.node_body[feet[side].node])
        knee_node = keypoint_nodes.get(f"{side}_knee")
        shin = -1 if knee_node is None else int(tree.node_body[knee_node])
        foot_bodies |= {b for b in range(1, m.nbody) if fb in ancestors(b) or int(parent[fb]) == b != shin}
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
        skip = (
            set(ancestors(bi)) - (trunk or set())
        ) | foot_bodies  # the arm's own chain (the trunk is fair game)
        for j, bj in enumerate(body_of):
            if bj in skip or bi in ancestors(bj):
                continue
            if bj in arm and (arm[bj] == arm[bi] or j < i):
                continue  # same arm, or an arm-arm pair already listed
            first.append(i)
            second.append(j)
    # A hand against its own shoulder (a hand brought to the shoulder, a folded arm): the
    # shoulder chain above the upper arm, which the pairs above leave out as the arm's own.
    # Kept only where they are apart at rest (a short arm's hand hangs next to its upper link).
    arm_pairs = len(first)  # the pairs so far: an arm against the trunk, the legs, the other arm
    hand_pairs: list[int] = []  # indices into first/second
    for i, bi in enumerate(body_of):
        if bi not in hands:
            continue
        for j, bj in enumerate(body_of):
            if bj in shoulders[hands[bi]] - (trunk or set()):
                hand_pairs.append(len(first))
                first.append(i)
                second.append(j)
    # Within a hand: links that branch from it (the CMU humanoid's fingers and thumb), which
    # nothing else keeps apart: a pair pushing the thumb out of a shin turns it into the fingers.
    # Where MuJoCo collides them, with the rest distance less REST_SLACK where that is below
    # the margin (fingers side by side, their enclosures overlapping at rest: PHC's G1).
    finger_pairs: list[int] = []  # indices into first/second
    excluded = excluded_body_pairs(m)
    hand_ancestors = {b: set(ancestors(b)) for b in hands}
    for i, bi in enumerate(body_of):
        for j, bj in enumerate(body_of):
            if (
                j > i
                and bi in hands
                and hands.get(bj) == hands[bi]
                and bi not in hand_ancestors[bj]
                and bj not in hand_ancestors[bi]
                and frozenset((bi, bj)) not in excluded
                and _collides(m, int(geom[i]), int(geom[j]))
            ):
                finger_pairs.append(len(first))
                first.append(i)
                second.append(j)
    for i, bi in enumerate(body_of):  # left leg against right leg (crossing steps, turned-out hips)
        if leg.get(bi) != 0:
            continue
        for j, bj in enumerate(body_of):
            if leg.get(bj) == 1:
                first.append(i)
                second.append(j)
    # Within a leg: the thigh against the foot and the links between the knee and the foot (a
    # deep crouch folds a short leg's foot onto its hip).
    for side in ("left", "right"):
        if f"{side}_knee" not in keypoint_nodes:
            continue
        knee = int(tree.node_body[keypoint_nodes[f"{side}_knee"]])
        upper = {b for b in ancestors(knee)[1:] if b in leg}
        lower = {b for b in leg if knee in ancestors(b) and b != knee}
        for i, bi in enumerate(body_of):
            if bi in upper:
                for j, bj in enumerate(body_of):
                    if bj in lower:
                        first.append(i)
                        second.append(j)
    # The shin against its own foot below the ankle link (loco-mujoco's skeleton: its tibia
    # mesh onto its heel bone as the ankle flexes), where the model does not exclude the pair;
    # calibrated on the real geoms by a sweep of the ankle's joints, and dropped where they
    # never touch within the joints' ranges (robots built not to).
    shin_pairs: list[int] = []  # indices into first/second
    for side in ("left", "right"):
        if f"{side}_knee" not in keypoint_nodes:
            continue
        knee = int(tree.node_body[keypoint_nodes[f"{side}_knee"]])
        below = {b for b in leg if knee in ancestors(b) and int(parent[b]) != knee and b != knee}
        for i, bi in enumerate(body_of):
            if bi != knee:
                continue
            for j, bj in enumerate(body_of):
                if (
                    bj in below
                    and frozenset((bi, bj)) not in excluded
                    and _collides(m, int(geom[i]), int(geom[j]))
                ):
                    shin_pairs.append(len(first))
                    first.append(i)
                    second.append(j)

    # The trunk against the thighs (a deep stoop or crouch folds the trunk onto the hips): the
    # trunk bodies the leg hangs from (the pelvis) against the links above each knee, but for a
    # parent and its child and body pairs the model excludes (as MuJoCo does).
    def exact_pair(i: int, j: int) -> bool:
        """Capsules ``i`` and ``j`` are their geoms (capsules, spheres), which MuJoCo collides."""
        gi, gj = int(geom[i]), int(geom[j])
        return bool(m.geom_type[gi] in _EXACT and m.geom_type[gj] in _EXACT and _collides(m, gi, gj))

    trunk_bodies = (trunk or set()) | shared

    def colliding_pair(i: int, j: int) -> bool:
        """Capsules ``i`` and ``j`` enclose geoms that MuJoCo collides."""
        return _collides(m, int(geom[i]), int(geom[j]))

    def against_trunk(links: set[int], colliding: bool = False) -> list[int]:
        """Appends the pairs of the trunk's capsules with those on ``links`` (bodies), only
        :func:`colliding_pair` ones if ``colliding``; their indices."""
        added: list[int] = []
        for i, bi in enumerate(body_of):
            if bi not in trunk_bodies:
                continue
            for j, bj in enumerate(body_of):
                if (
                    bj in links
                    and int(parent[bj]) != bi
                    and frozenset((bi, bj)) not in excluded
                    and (not colliding or colliding_pair(i, j))
                ):
                    added.append(len(first))
                    first.append(i)
                    second.append(j)
        return added

    trunk_pairs: list[int] = []  # indices into first/second
    for side in ("left", "right"):
        if f"{side}_knee" in keypoint_nodes:
            knee = int(tree.node_body[keypoint_nodes[f"{side}_knee"]])
            trunk_pairs += against_trunk({b for b in ancestors(knee)[1:] if b in leg})
    # Enclosing capsules are loose around meshes (exact around capsules, close around
    # cylinders): pairs with a mesh may let their enclosures overlap in a first solve
    # (SelfClearance.relaxed). Arms brought that close to the trunk roll their shoulder links
    # (the chain from the trunk to the shoulder keypoint) into it: then those are kept from the
    # trunk too, calibrated like the thighs.
    mesh = m.geom_type[np.asarray(geom)] == mujoco.mjtGeom.mjGEOM_MESH
    loose = any(mesh[first[k]] or mesh[second[k]] for k in range(arm_pairs))
    shoulder_pairs: list[int] = []
    spine_pairs: list[int] = []
    if loose:
        for shoulder_chain in shoulders.values():
            shoulder_pairs += against_trunk(shoulder_chain - trunk_bodies)
    else:
        # Robots of primitive geoms: the upper arm rolls into the chest as the clavicle lifts
        # (the CMU humanoid's capsules; the MIT humanoid's cylinder upper arm into its box
        # torso: 254 frames, 33 mm deep), and a jointed spine bends the pelvis onto the upper
        # back. Kept apart in every solve: the trunk against the shoulder links where MuJoCo
        # collides their geoms (boxes' and cylinders' enclosures calibrated like the thighs'),
        # trunk links that are not parent and child where both geoms are capsules or spheres
        # (their enclosures exact).
        for shoulder_chain in shoulders.values():
            shoulder_pairs += against_trunk(shoulder_chain - trunk_bodies, colliding=True)
        on_trunk = [i for i, b in enumerate(body_of) if b in trunk_bodies]
        for i in on_trunk:
            for j in on_trunk:
                bi, bj = body_of[i], body_of[j]
                if (
                    bi in ancestors(bj)
                    and bi not in (bj, int(parent[bj]))
                    and frozenset((bi, bj)) not in excluded
                    and exact_pair(i, j)
                ):
                    spine_pairs.append(len(first))
                    first.append(i)
                    second.append(j)
        # A jointed neck (SMPL's, +-180 degrees) folds the head onto a clavicle: the bodies
        # above the trunk that are neither arm nor shoulder chain against the shoulder chains.
        chains = set().union(*shoulders.values()) - trunk_bodies if shoulders else set()
        head = {b for b in range(1, m.nbody) if int(parent[b]) in trunk_bodies} - trunk_bodies - chains
        head = {b for b in range(1, m.nbody) if head & set(ancestors(b))} - set(leg) - set(arm)
        for i, bi in enumerate(body_of):
            if bi in head:
                for j, bj in enumerate(body_of):
                    if bj in chains and exact_pair(i, j):
                        spine_pairs.append(len(first))
                        first.append(i)
                        second.append(j)
    trunk_pairs += shoulder_pairs
    relaxed_only = shoulder_pairs if loose else []
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
    rest_dist, _, _ = capsule_distances(rest, sc)
    # The rest pose is collision free: pairs closer than the margin there may come that close.
    margin = np.minimum(SELF_MARGIN, rest_dist[0] - REST_SLACK)
    keep = np.ones(len(first), dtype=bool)
    keep[hand_pairs] = rest_dist[0, hand_pairs] >= SELF_MARGIN + REST_SLACK
    keep[spine_pairs] = rest_dist[0, spine_pairs] >= SELF_MARGIN + REST_SLACK
    margin[spine_pairs] = TRUNK_MARGIN
    # Trunk pairs whose enclosures are close at rest, and the shin pairs: calibrated on the
    # real geometry.
    calibrate = [k for k in trunk_pairs if rest_dist[0, k] - REST_SLACK < TRUNK_MARGIN]
    swept = swept_margins(model, tree, sc, calibrate + shin_pairs)
    for k in trunk_pairs:
        margin[k] = min(margin[k], TRUNK_MARGIN)
        if k in swept:
            found = swept[k]
            if found is None:
                keep[k] = False  # never touching in the sweep, or not sweepable
            else:
                margin[k] = min(found, margin[k])
    for k in shin_pairs:
        found = swept[k]
        keep[k] = found is not None
        margin[k] = min(margin[k], TRUNK_MARGIN, np.inf if found is None else found)
    loose_radius = np.where(mesh, np.asarray(radius), 0.0)
    looseness = loose_radius[np.asarray(first)] + loose_radius[np.asarray(second)]
    looseness[arm_pairs : arm_pairs + len(hand_pairs)] = 0.0
    looseness[shoulder_pairs] = 0.0
    full = SelfClearance(
        sc.node,
        sc.p0,
        sc.p1,
        sc.radius,
        sc.first[keep],
        sc.second[keep],
        sc.geom,
        margin[keep],
        looseness=looseness[keep],
    )
    # The trunk-shoulder pairs belong to the relaxed solve only: the safe margins keep the arms
    # away without them (and the safe solve stays what it was before the relaxed one existed).
    is_shoulder = np.zeros(len(first), dtype=bool)
    is_shoulder[relaxed_only] = True
    safe = ~is_shoulder[keep]
    if safe.all():
        return full
    return replace(
        full,
        first=full.first[safe],
        second=full.second[safe],
        margin=full.margin[safe],
        looseness=looseness[keep][safe],
        relaxed_pairs=full,
    )


SWEEP_STEPS = 9
"""Values per joint of the sweep that calibrates a pair (:func:`swept_margins`)."""
SWEEP_DEPTH = 0.002
"""Metres deep the swept geoms must overlap to count as touching (the solver's own tolerance)."""
SWEEP_JOINTS = 4
"""Most joints between the two bodies of a pair that :func:`swept_margins` sweeps."""
SWEEP_SLACK = 0.002
"""Metres added to the largest capsule distance at which the swept geoms touch."""


def swept_margins(
    model: mujoco.MjModel, tree: KinematicTree, sc: SelfClearance, pairs: list[int]
) -> dict[int, float | None]:
    """The margin of each pair of ``pairs`` (two bodies a few joints apart: a trunk body and a
    thigh link, a shin and its foot, a waist link beside a hip) from its real geoms.

    Enclosing capsules of a pelvis and the hip link hanging below it overlap in every pose
    (G1's by 1-5 cm), so the rest pose's distance says nothing about contact. The joints
    between the two bodies (at most ``SWEEP_JOINTS``) are swept over their ranges
    (``SWEEP_STEPS`` values each, +-pi for unlimited ones), the geoms' own distance measured
    by MuJoCo (``mj_geomDistance``, convex hulls for meshes) where their capsules overlap
    (the capsules enclose them): the margin is the largest capsule distance of a pose where
    they overlap by more than ``SWEEP_DEPTH``, plus ``SWEEP_SLACK`` (the grid is coarse: off
    it, overlaps up to about 8 mm may stay above the margin, checked in the tests;
    ``controlmm validate`` allows 5 mm). None: no swept pose makes them touch, or the pair
    cannot be swept (more than ``SWEEP_JOINTS`` joints lie between them: on the paths from
    the two bodies up to their common ancestor) or need not be (no joint between them). The
    pairs of one body pair share their sweep (a body split into convex pieces has hundreds of
    pairs with the next).
    """
    out: dict[int, float | None] = {}
    by_bodies: dict[tuple[int, int], list[int]] = {}
    for k in sorted(pairs):
        key = (int(tree.node_body[sc.node[sc.first[k]]]), int(tree.node_body[sc.node[sc.second[k]]]))
        by_bodies.setdefault(key, []).append(k)
    data = mujoco.MjData(model)
    for (body1, body2), ks in by_bodies.items():
        joints = _joints_between(model, body1, body2)
        if not joints or len(joints) > SWEEP_JOINTS:  # none: welded together, they never move
            out.update(dict.fromkeys(ks))
            continue
        col = [int(np.flatnonzero(tree.joint_ids == j)[0]) for j in joints]
        lo = np.clip(tree.lower[col], -np.pi, np.pi)
        hi = np.clip(tree.upper[col], -np.pi, np.pi)
        grid = np.stack(
            np.meshgrid(*(np.linspace(a, b_, SWEEP_STEPS) for a, b_ in zip(lo, hi, strict=True))), -1
        ).reshape(-1, len(col))
        q = np.tile(tree.qpos0, (len(grid), 1))
        q[:, col] = grid
        n = len(q)
        poses = tree.forward(np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), q)
        first, second = sc.first[ks], sc.second[ks]
        capsule, _, _ = capsule_distances(
            poses, sc.select_pairs(np.isin(np.arange(sc.num_pairs), ks))
        )  # (n, K)
        adr = model.jnt_qposadr[joints]
        g1, g2 = sc.geom[first], sc.geom[second]
        touching = np.zeros_like(capsule, dtype=bool)
        # The capsules enclose the geoms: the geoms overlap only where the capsules overlap (as
        # deep but for a flat cylinder's, fit to 16 points of each rim: SWEEP_DEPTH of slack).
        near = capsule < 0.0
        for t in np.flatnonzero(near.any(axis=1)):
            data.qpos[:] = model.qpos0
            data.qpos[adr] = grid[t]
            mujoco.mj_kinematics(model, data)
            for p in np.flatnonzero(near[t]):
                dist = mujoco.mj_geomDistance(model, data, int(g1[p]), int(g2[p]), 0.05, None)
                touching[t, p] = dist < -SWEEP_DEPTH
        for c, k in enumerate(ks):
            out[k] = float(capsule[touching[:, c], c].max()) + SWEEP_SLACK if touching[:, c].any() else None
    return out


def _joints_between(model: mujoco.MjModel, first: int, second: int) -> list[int]:
    """The joints that move body ``second`` relative to body ``first``: those of the bodies
    from each up to (not including) their deepest common ancestor (the trunk body above a
    thigh link; the pelvis for a waist link and a hip link hanging from it side by side)."""
    above, b = set(), first
    while b > 0:
        above.add(b)
        b = int(model.body_parentid[b])
    joints: list[int] = []
    b = second
    while b > 0 and b not in above:
        joints += range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b]))
        b = int(model.body_parentid[b])
    common = b
    b = first
    while b != common and b > 0:
        joints += range(int(model.body_jntadr[b]), int(model.body_jntadr[b] + model.body_jntnum[b]))
        b = int(model.body_parentid[b])
    return joints
