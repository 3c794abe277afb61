"""The solver's self-clearance checked on the robot's real collision geometry.

The solver keeps capsules apart (:mod:`retarget.selfcollision`); the capsules *enclose* the
collision geoms, loosely around meshes (G1's forearm and thigh meshes by 1-3 cm), so a margin
that is safe in every pose keeps the arms further from the thighs and trunk than the robot
needs, and the fit to the human pays for it (a deep stoop, corpus clip 000000: 3.9 cm mean
keypoint error with the safe margins, 2.8 cm after this check).

So where a robot has mesh geoms the first solve lets each pair's capsules come closer than
their safe margin by ``RELAX_FRACTION`` of their looseness, at most ``RELAX_MOST``
(:meth:`SelfClearance.relaxed`); then the solver's frames are replayed in MuJoCo
(:func:`penetration_depths`: ``mj_collision`` on the
MJCF's own geoms, its exclusions honoured, as ``controlmm validate`` measures it), and the
pairs whose geoms overlap deeper than their tolerance (``CHECK_DEPTH`` for the relaxed ones,
``OTHER_DEPTH`` for the others) get their safe margin back or, already there (the margin is
a soft penalty), a margin larger by the overlap found (:meth:`SelfClearance.tightened`), for
another solve; after ``RELAXED_SOLVES`` relaxed solves that still overlap, or one that
overlaps deeper than ``RETRY_DEPTH``, the safe margins everywhere (the solve of a robot
without meshes), checked the same way: pairs still deeper than ``OTHER_DEPTH`` (an enclosure
pair that overlaps at rest has a negative margin, a soft one) get that much more room for a
last solve. A robot whose capsules are its geoms (no meshes) starts from the safe margins,
checked the same way, with more room and a stiffer weight where they still overlap
(``EXACT_TIGHTENINGS``). Every robot's output frames are checked at the end (``OUTPUT_SELF``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from retarget.actuators import DEFAULT_VELOCITY_LIMIT
from retarget.geoms import excluded_body_pairs
from retarget.kinematics import KinematicTree, Poses, quat_to_mat
from retarget.selfcollision import REST_SLACK, SELF_MARGIN, SelfClearance, capsule_distances, close_pairs

RELAX_FRACTION = 0.3
"""In the first solve a pair's capsules may come closer than their safe margin by this
fraction of their looseness (the radii of its capsules around meshes; G1's forearm against
a thigh: 0.3 x (0.04 + 0.06) m = 3 cm, so a 2 cm margin becomes a 1 cm overlap; OP3, a third
of G1's size, about 1.5 cm). Chosen on 40 corpus clips (G1) and 30 (OP3): 0.5 fitted no
closer and failed more often."""
RELAX_MOST = 0.04
"""...but by at most this (m): the trunk's and a thigh's big meshes (0.3 x their radii: 6 cm)
would otherwise overlap in the first solve and cost another; capped, fewer G1 clips need a
second solve (40 corpus clips: 1.08 solves instead of 1.15) at the same fit (3 cm: 1.03
solves, but the stoop 000000 at 3.0 cm instead of 2.8)."""
CHECK_DEPTH = 0.002
"""Real geoms of a relaxed pair overlapping deeper than this (m) send it back to its safe
margin (``controlmm validate`` fails a self-collision deeper than 5 mm)."""
OTHER_DEPTH = 0.004
"""The other pairs (kept at their safe margins; a pelvis and a hip link overlap 2-3 mm with
the safe margins too) and geoms the solver does not keep apart may overlap this much (m)."""
RELAXED_SOLVES = 2
"""Relaxed solves at most (the first one, then more room where it overlapped); still
overlapping after them, the safe margins everywhere (one more solve)."""
OUTPUT_SELF = (3.0, 10.0, 30.0)
"""Where the output frames still overlap deeper than ``OTHER_DEPTH`` after all that (the solver's
frames clear but an arm sweeping through a hip between two of them, or a hand target deep in
the body that a soft margin gives way to), the motion is solved again at the output rate
(nothing in between frames) with the self-clearance weight these many times its own, one solve
each while the overlap lasts, the pairs still overlapping getting that much more room for the
next (G1's pelvis and a hip link in a stoop, corpus clip 000005 at 30 fps: 8 mm after the
first); each kept if it overlaps less. x10 at once lifted a seated G1's planted foot 15 cm
(clip 000012 at 30 fps: the solve stopped in a poor minimum). The third rung: G1's stoop
000005 at 30 fps left the right shoulder 6.0 and 5.8 mm inside the torso after x3 and x10,
none after x30 (with the coarse level's schedule before 2026-12-02; since, x10 clears it).
A rung whose solve is not kept clear is solved again with the planted feet's locks that many
times stiffer too (:func:`retarget.targets.stiffer_locks`): the arms give way, not the feet."""
OUTPUT_SLIP = 0.015
"""...and only if no foot that the human keeps down slides further between two output frames
than before and than this (m): a solve with another weight may settle elsewhere (x3 and
x10 slid H1's planted feet 2 cm a frame in a sit-down, corpus clip 000012 at 50 fps; x30
did not).
Solves at the output rate hold planted feet less tightly than the resampled ones (no
pinning between frames: 0.8-1.3 cm a frame against 0.1-0.3 on G1's stoop 000005 and H1's
000012), so "no more than before" alone would keep their overlaps."""
OUTPUT_SPEED = DEFAULT_VELOCITY_LIMIT
"""...and only if it turns no joint faster than before and than this (rad/s; the speed limit
``controlmm validate`` applies to joints without a published one,
:data:`retarget.actuators.DEFAULT_VELOCITY_LIMIT`): the room the stiffer solves give a pair
may spin an unobserved joint (an SMPL humanoid's free wrist sitting down, corpus clip 000012
at 30 fps: 5.8 times its speed limit)."""
OUTPUT_FIT_GIVE = 0.02
"""...and only if its keypoints stay within this (m, mean over keypoints and frames) of as
close to their targets as the output check's first solve was; one that clears every overlap
by giving up more of the motion is kept only where no later solve clears within it (the AMP
humanoid's kneel at 50 fps: a 3x stiffer solve with the feet as stiff cleared a hand 2 cm in
a thigh with its keypoints 3.6 cm further from their targets, the 10x one clears it 4 cm
closer than the first solve)."""
OUTPUT_LIFT = 0.01
"""...and only if its output is lifted off the floor (:func:`retarget.retarget_motion.lift_above_floor`:
some geom was below it) no more than before and than this (m): the whole robot goes up,
planted feet hovering. A stiff-lock rung cleared the converted Valkyrie's squat (corpus clip
000000 at 30 fps) with a geom 35 mm under the floor, and its fit went from 13.4 to 20.1 cm;
refused, the next rung clears it at 13.1 cm."""
OUTPUT_FAR_DEPTH = 0.005
"""...and then only where the closer solve kept still overlaps deeper than this (m: what
``controlmm validate`` fails); G1 with hands sitting down (corpus clip 65 at 30 fps) kept a
clear solve 3 cm further from its targets, with a thumb past its velocity limit, over one
4.5 mm in."""
OUTPUT_NEAR_GIVE = 0.005
"""...and where the solve kept overlaps no deeper than ``OUTPUT_FAR_DEPTH`` already (it passes
``controlmm validate``), a later one is kept only if its keypoints end no further than this
(m, mean) from their targets than that one's: ToddlerBot clapping (the first clip of the corpus
family ``clap``) kept a solve 4.1 mm into its waist box, then one clear of it that fitted the
human at 6.1 cm instead of 2.9 (3.2 with this rule)."""
EXACT_TIGHTENINGS = 2
"""A robot whose capsules are its geoms (no loose enclosures: Apollo) is solved with the safe
margins; pairs whose geoms still overlap deeper than ``OTHER_DEPTH`` (Apollo's thighs, 10.5 cm
capsules 2 cm apart at rest, in a turn: 3-4 cm) get that much more room for another solve, at
most this many times, with the self-clearance weight ``EXACT_SELF`` times its own."""
EXACT_SELF = 3.0
"""Chosen on Apollo's turns (corpus clips 000006, 000009, 000013): 1 left 7-8 mm overlaps after
two more solves, 10 cleared them with knees snapping faster than their velocity limits."""
RETRY_DEPTH = 0.01
"""A relaxed solve whose real geoms overlap deeper than this (m) somewhere (arms pressed into
the body: hands on the knees, a crouch) goes to the safe margins at once: more room for a few
pairs did not clear such solves on the 27 clips of ``benchmarks/retarget.py`` (3 solves where
2 do)."""


CALIBRATION_SLACK = 0.02
"""How far (m) outside its margin a pair whose enclosures overlap at rest is still replayed
for real overlaps: the margins are calibrated on a sweep of a few joints, and between its
poses PHC's H1 turning on the real clip had its torso and right shoulder geoms 6.5 mm into
each other with their capsules 4.3 mm outside the margin, unseen; over 3,000 random poses of
the packaged G1, shoulder-yaw links 5 mm or more inside the torso lay up to 1.7 cm outside."""


def penetration_depths(
    model: mujoco.MjModel,
    tree: KinematicTree,
    qpos: np.ndarray,
    sc: SelfClearance,
    other_depth: float = OTHER_DEPTH,
    every_frame: bool = False,
) -> np.ndarray:
    """(P,) deepest overlap (m, 0 where none) of each pair's real geoms over the frames of
    ``qpos`` (T, nq), by MuJoCo's own collision detection of the robot's model (its exclusions
    honoured). Unless ``every_frame`` (the output check), only the frames where some pair's
    capsules overlap (or, for pairs that overlap at rest, come within CALIBRATION_SLACK of
    their margin) are replayed: elsewhere their geoms cannot overlap (or hardly: the margins
    are calibrated on a sweep of a few joints). Two other
    geoms of the robot overlapping deeper than ``other_depth`` there (bodies the solver does
    not keep apart, pushed together by the closer pairs) count against the relaxed pairs of
    the subtree below the deeper of the two bodies (that arm)."""
    found = np.zeros(sc.num_pairs)
    safe = sc.margin if sc.safe_margin is None else sc.safe_margin
    relaxed = sc.margin < safe
    pair_of = _pair_index(sc)
    root = model.body_rootid[model.geom_bodyid]
    for _, g1, g2, depth in _overlaps(model, tree, qpos, sc, every_frame):
        k = pair_of.get(g1, g2)
        if k is not None:
            found[k] = np.maximum(found[k], depth)
        elif depth > other_depth and root[g1] == root[g2]:
            b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
            arm = relaxed & _in_subtree(model, sc, b1 if _depth(model, b1) >= _depth(model, b2) else b2)
            found[arm] = np.maximum(found[arm], depth)
    return found


def unpaired_overlaps(
    model: mujoco.MjModel,
    tree: KinematicTree,
    qpos: np.ndarray,
    sc: SelfClearance,
    rest: Poses,
    depth: float = OTHER_DEPTH,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capsule pairs (first, second: (Q,) indices into ``sc``'s capsules) whose geoms overlap
    deeper than ``depth`` (m) in some frame of ``qpos`` (T, nq) but that ``sc`` does not keep
    apart, with their margins (Q,): ``SELF_MARGIN``, or the rest distance less ``REST_SLACK``
    where that is smaller. A free ball wrist folding a hand into its own forearm, a free neck
    folding the head onto a clavicle (SMPL humanoids): geoms the pairs built from the anatomy
    (:func:`retarget.selfcollision.build_self_clearance`) leave alone.

    Candidates: the geom pairs MuJoCo collides (contype/conaffinity; not one body or a parent
    and its child after welding; not excluded) whose capsules are apart at rest (``rest``, one
    frame; capsules that overlap there touch by design); only where their capsules overlap
    (they enclose the geoms) are the geoms measured (``mj_geomDistance``)."""
    qpos = np.asarray(qpos, dtype=np.float64)
    none = np.zeros(0, dtype=int)
    first, second = np.triu_indices(len(sc.geom) - sc.balls, 1)  # the geoms' enclosures
    g1, g2 = sc.geom[first], sc.geom[second]
    weld = model.body_weldid[model.geom_bodyid]
    w1, w2 = weld[g1], weld[g2]
    up1, up2 = model.body_weldid[model.body_parentid[w1]], model.body_weldid[model.body_parentid[w2]]
    excluded = excluded_body_pairs(model)
    bodies = model.geom_bodyid
    keep = ~_pair_index(sc).contains(g1, g2)
    keep &= (
        (w1 != w2)
        & (up1 != w2)
        & (up2 != w1)
        & (
            (
                (model.geom_contype[g1] & model.geom_conaffinity[g2])
                | (model.geom_contype[g2] & model.geom_conaffinity[g1])
            )
            != 0
        )
    )
    keep[keep] = [
        frozenset((int(bodies[a]), int(bodies[b]))) not in excluded
        for a, b in zip(g1[keep], g2[keep], strict=True)
    ]
    first, second = first[keep], second[keep]
    if not first.size:
        return none, none, np.zeros(0)
    cand = sc.with_pairs(first, second, 0.0).select_pairs(
        np.arange(sc.num_pairs + len(first)) >= sc.num_pairs
    )
    at_rest = capsule_distances(rest, cand)[0][0]
    apart = at_rest > 2 * REST_SLACK
    first, second, at_rest, cand = first[apart], second[apart], at_rest[apart], cand.select_pairs(apart)
    if not first.size:
        return none, none, np.zeros(0)
    poses = tree.forward(qpos[:, :3], quat_to_mat(qpos[:, 3:7]), qpos[:, 7:])
    near = close_pairs(poses, replace(cand, margin=np.zeros(cand.num_pairs)))
    gap = geom_distances(
        model, qpos, near.frame, cand.geom[cand.first[near.pair]], cand.geom[cand.second[near.pair]], 0.01
    )
    found = np.zeros(cand.num_pairs, dtype=bool)
    found[near.pair[gap < -depth]] = True
    return first[found], second[found], np.minimum(SELF_MARGIN, at_rest[found] - REST_SLACK)


def geom_distances(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    frame: np.ndarray,
    geom1: np.ndarray,
    geom2: np.ndarray,
    cutoff: float,
) -> np.ndarray:
    """(E,) MuJoCo's distance (m; negative: their overlap) between geoms ``geom1[e]`` and
    ``geom2[e]`` in frame ``frame[e]`` of ``qpos`` (T, nq) (``mj_geomDistance``: convex hulls
    for meshes; ``cutoff`` where they are further apart), each frame placed once."""
    out = np.full(len(frame), float(cutoff))
    data = mujoco.MjData(model)
    order = np.argsort(frame, kind="stable")
    bounds = np.flatnonzero(np.diff(frame[order])) + 1
    for group in np.split(order, bounds) if len(order) else []:
        data.qpos[:] = qpos[frame[group[0]]]
        mujoco.mj_kinematics(model, data)
        for e in group:
            out[e] = mujoco.mj_geomDistance(model, data, int(geom1[e]), int(geom2[e]), cutoff, None)
    return out


BALL_RADIUS = 0.01
"""Radius (m) of the balls :func:`contact_balls` holds where two geoms touch (at least the
overlap found, so that the two balls overlap by as much as the geoms do)."""
BALL_MARGIN = 0.005
"""Metres the solver keeps between two such balls (soft: a few mm in is what it leaves)."""
BALLS_PER_PAIR = 4
"""At most this many ball pairs per geom pair, the deepest contacts first."""
_OWN_CAPSULE = (int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE))


def contact_balls(
    model: mujoco.MjModel,
    tree: KinematicTree,
    qpos: np.ndarray,
    sc: SelfClearance,
    depth: float = OTHER_DEPTH,
    inside_rest_overlap: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Balls (:meth:`SelfClearance.with_balls`) where two geoms that ``sc`` keeps apart overlap
    deeper than ``depth`` (m) in frames of ``qpos`` (T, nq) and one of them is not its own
    capsule (a cylinder, box or mesh: its enclosure may not see the contact), where their
    enclosures are outside their pair's margin (inside it they are pushed apart already) or,
    with ``inside_rest_overlap``, inside a negative one (enclosures that overlap at rest do
    not see the contact wherever they are). Kuavo's thighs
    are cylinders across the hips, 14 cm long with flat ends 3 cm apart; their enclosing
    capsules reach 6 cm past those ends, overlap by 9 cm at rest, and a hip yaw that swings
    the rims together moves them apart. Per contact (MuJoCo's, the normal from the first geom
    to the second), a ball in each geom tangent inside its surface at the deepest point, in
    its body's frame: the two balls overlap by as much as the geoms there and part as those
    points part. Up to BALLS_PER_PAIR per geom pair, deepest first, none within a ball radius
    of one taken before on the same geom (those already in ``sc`` included).

    Returns node (Q, 2), centre (Q, 2, 3) in the nodes' frames, radius (Q, 2) m, geom (Q, 2)."""
    qpos = np.asarray(qpos, dtype=np.float64)
    pair_of = _pair_index(sc)
    data = mujoco.MjData(model)
    found: dict[tuple[int, int], list[tuple[float, int, np.ndarray, np.ndarray]]] = {}
    for frame in range(len(qpos)):  # (overlap, frame, contact point, normal) per geom pair
        data.qpos[:] = qpos[frame]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        for con in data.contact[: data.ncon]:
            g1, g2 = int(con.geom[0]), int(con.geom[1])
            exact = int(model.geom_type[g1]) in _OWN_CAPSULE and int(model.geom_type[g2]) in _OWN_CAPSULE
            if con.dist < -depth and not exact and pair_of.get(g1, g2) is not None:
                found.setdefault((g1, g2), []).append(
                    (-float(con.dist), frame, con.pos.copy(), con.frame[:3].copy())
                )
    taken: dict[int, list[np.ndarray]] = {}  # ball centres per geom, in its body's frame
    for c in range(len(sc.geom) - sc.balls, len(sc.geom)):
        taken.setdefault(int(sc.geom[c]), []).append(sc.p0[c])
    node, centre, radius, geom = [], [], [], []
    for (g1, g2), hits in found.items():
        paired = pair_of.get(g1, g2)
        assert paired is not None  # found only holds paired geoms
        enclosures = sc.select_pairs(np.arange(sc.num_pairs) == paired[0])
        nodes = [tree.node_of_body(int(model.geom_bodyid[g])) for g in (g1, g2)]
        kept = 0
        for overlap, frame, pos, normal in sorted(hits, key=lambda hit: -hit[0]):
            if kept == BALLS_PER_PAIR:
                break
            q = qpos[frame : frame + 1]
            poses = tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:])
            inside = capsule_distances(poses, enclosures)[0][0, 0] < enclosures.margin[0]
            if inside and not (inside_rest_overlap and enclosures.margin[0] < 0.0):
                continue  # the enclosures are within their margin there: they push already
            # Tangent inside each geom at its deepest point (``pos`` lies halfway between the two
            # surfaces, the normal points from the first geom to the second), in its body's frame.
            r = max(BALL_RADIUS, overlap)
            inward = (0.5 * overlap - r) * normal
            local = [
                poses.rot[0, n].T @ (world - poses.pos[0, n])
                for n, world in zip(nodes, (pos + inward, pos - inward), strict=True)
            ]
            pairs = list(zip((g1, g2), local, strict=True))
            if any(np.linalg.norm(p - at) < r for g, at in pairs for p in taken.get(g, [])):
                continue  # a ball held there already
            for g, at in pairs:
                taken.setdefault(g, []).append(at)
            node.append(nodes)
            centre.append(local)
            radius.append([r, r])
            geom.append([g1, g2])
            kept += 1
    return (
        np.array(node, dtype=int).reshape(-1, 2),
        np.array(centre).reshape(-1, 2, 3),
        np.array(radius).reshape(-1, 2),
        np.array(geom, dtype=int).reshape(-1, 2),
    )


def pair_overlaps(
    model: mujoco.MjModel, tree: KinematicTree, qpos: np.ndarray, sc: SelfClearance, every_frame: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the pairs' real geoms overlap in the frames of ``qpos`` (T, nq), measured as
    :func:`penetration_depths` measures it (only the pairs themselves): (N,) frames, (N,) pairs
    and (N,) depths (m, > 0), one entry per overlapping (frame, pair) with its deepest overlap,
    sorted by frame, then pair. Sparse: a robot split into convex pieces has 455,000 pairs."""
    pair_of = _pair_index(sc)
    found: list[tuple[int, np.ndarray, float]] = []
    for frame, g1, g2, depth in _overlaps(model, tree, qpos, sc, every_frame):
        k = pair_of.get(g1, g2)
        if k is not None:
            found.append((frame, k, depth))
    if not found:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
    frames = np.concatenate([np.full(len(k), f, dtype=np.int64) for f, k, _ in found])
    pairs = np.concatenate([k for _, k, _ in found]).astype(np.int64)
    depths = np.concatenate([np.full(len(k), d) for _, k, d in found])
    key = frames * sc.num_pairs + pairs
    order = np.lexsort((-depths, key))  # by key, the deepest first
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    keep = order[first]
    return frames[keep], pairs[keep], depths[keep]


def overlap_gaps(
    model: mujoco.MjModel, tree: KinematicTree, qpos: np.ndarray, sc: SelfClearance
) -> np.ndarray:
    """(P,) each pair's capsule distance (m) in the frame of ``qpos`` (T, nq) where its real
    geoms overlap deepest (:func:`pair_overlaps`); -inf where they do not overlap."""
    pair_of = _pair_index(sc)
    deepest = np.zeros(sc.num_pairs)
    frame_of = np.zeros(sc.num_pairs, dtype=int)
    for frame, g1, g2, depth in _overlaps(model, tree, qpos, sc, every_frame=True):
        k = pair_of.get(g1, g2)
        if k is not None:  # the first frame of the deepest overlap
            deeper = k[depth > deepest[k]]
            deepest[deeper] = depth
            frame_of[deeper] = frame
    gaps = np.full(sc.num_pairs, -np.inf)
    hit = np.flatnonzero(deepest > 0.0)
    if hit.size:
        q = np.asarray(qpos, dtype=np.float64)[frame_of[hit]]
        poses = tree.forward(q[:, :3], quat_to_mat(q[:, 3:7]), q[:, 7:])
        keep = np.zeros(sc.num_pairs, dtype=bool)
        keep[hit] = True
        gaps[hit] = np.diagonal(capsule_distances(poses, sc.select_pairs(keep))[0])
    return gaps


def overlap_frames(model: mujoco.MjModel, qpos: np.ndarray, depth: float = OUTPUT_FAR_DEPTH) -> int:
    """Frames of ``qpos`` (T, nq) in which two geoms of the robot overlap deeper than ``depth``
    (m), by ``mj_collision`` (the model's exclusions honoured), as ``controlmm validate`` counts
    self-collision frames (at the frames themselves)."""
    data = mujoco.MjData(model)
    root = model.body_rootid[model.geom_bodyid]
    count = 0
    for frame in np.asarray(qpos, dtype=np.float64):
        data.qpos[:] = frame
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        n = data.ncon
        g = data.contact.geom[:n]
        ours = (root[g[:, 0]] == root[g[:, 1]]) & (model.geom_bodyid[g[:, 0]] > 0)
        count += bool(np.any(data.contact.dist[:n][ours] < -depth))
    return count


@dataclass(frozen=True)
class _PairIndex:
    """Pair indices of each (geom, geom) of a clearance, both orders: their enclosures' pair and
    the pairs of balls held where the two touched (:func:`contact_balls`); an overlap of the two
    geoms counts for each. Sorted keys ``first_geom * span + second_geom`` (a robot split into
    convex pieces has 455,000 pairs: a dict of them took 0.5 s per check)."""

    keys: np.ndarray
    pair: np.ndarray
    span: int

    def get(self, g1: int, g2: int) -> np.ndarray | None:
        """The pairs (ascending) of geoms ``g1``, ``g2`` (either order); None: not paired."""
        if not (0 <= g1 < self.span and 0 <= g2 < self.span):  # a geom of none of the pairs
            return None
        key = g1 * self.span + g2
        lo, hi = np.searchsorted(self.keys, [key, key + 1])
        return self.pair[lo:hi] if hi > lo else None

    def contains(self, g1: np.ndarray, g2: np.ndarray) -> np.ndarray:
        """(N,) bool: geoms ``g1``, ``g2`` (N,) are paired."""
        g1, g2 = np.asarray(g1, dtype=np.int64), np.asarray(g2, dtype=np.int64)
        inside = (g1 >= 0) & (g1 < self.span) & (g2 >= 0) & (g2 < self.span)
        key = g1 * self.span + g2
        if not len(self.keys):
            return np.zeros(len(key), dtype=bool)
        at = np.minimum(np.searchsorted(self.keys, key), len(self.keys) - 1)
        return inside & (self.keys[at] == key)


def _pair_index(sc: SelfClearance) -> _PairIndex:
    """:class:`_PairIndex` of ``sc``."""
    a, b = sc.geom[sc.first].astype(np.int64), sc.geom[sc.second].astype(np.int64)
    span = int(max(sc.geom.max(initial=0), 0)) + 1
    k = np.arange(sc.num_pairs)
    other = a != b
    keys = np.concatenate([a * span + b, (b * span + a)[other]])
    pair = np.concatenate([k, k[other]])
    order = np.lexsort((pair, keys))
    return _PairIndex(keys[order], pair[order], span)


def _overlaps(
    model: mujoco.MjModel, tree: KinematicTree, qpos: np.ndarray, sc: SelfClearance, every_frame: bool = False
) -> Iterator[tuple[int, int, int, float]]:
    """(frame, geom, geom, depth > 0 in m) of every two of the model's geoms that overlap in
    the frames of ``qpos`` (T, nq) (``every_frame``) or those where some pair's capsules
    overlap (or, for pairs that overlap at rest, come within CALIBRATION_SLACK of their
    margin): ``mj_collision``, the model's exclusions honoured."""
    qpos = np.asarray(qpos, dtype=np.float64)
    safe = sc.margin if sc.safe_margin is None else sc.safe_margin
    poses = tree.forward(qpos[:, :3], quat_to_mat(qpos[:, 3:7]), qpos[:, 7:])
    # Capsules enclose their geoms: two geoms overlap only where their capsules do. Pairs whose
    # enclosures overlap at rest (negative safe margins, calibrated on the real geoms over a
    # sweep of a few joints) may overlap inside their margin, and a little outside it between
    # the sweep's poses (CALIBRATION_SLACK).
    maybe = np.where(safe >= 0.0, 0.0, np.maximum(sc.margin, safe) + CALIBRATION_SLACK)
    frames = (
        np.arange(len(qpos))
        if every_frame
        else np.unique(close_pairs(poses, replace(sc, margin=maybe)).frame)
    )
    data = mujoco.MjData(model)
    for frame in frames:
        data.qpos[:] = qpos[frame]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_collision(model, data)
        n = data.ncon
        deep = np.flatnonzero(data.contact.dist[:n] < 0.0)
        for (g1, g2), dist in zip(data.contact.geom[:n][deep], data.contact.dist[:n][deep], strict=True):
            yield int(frame), int(g1), int(g2), float(-dist)


def _depth(model: mujoco.MjModel, body: int) -> int:
    """Bodies between ``body`` and the world."""
    n = 0
    while body > 0:
        body, n = int(model.body_parentid[body]), n + 1
    return n


def _in_subtree(model: mujoco.MjModel, sc: SelfClearance, body: int) -> np.ndarray:
    """(P,) bool: pairs with a capsule on ``body`` or a body below it."""
    geom_body = model.geom_bodyid[sc.geom]
    below = np.zeros(len(geom_body), dtype=bool)
    for c, b in enumerate(geom_body):
        b = int(b)
        while b > 0 and b != body:
            b = int(model.body_parentid[b])
        below[c] = b == body
    return below[sc.first] | below[sc.second]
