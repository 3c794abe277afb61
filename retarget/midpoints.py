"""Self-clearance between two solver frames: the capsule pairs of the averaged poses.

The solver checks its capsule pairs (:mod:`retarget.selfcollision`) at its own frames (the
motion's 20 fps); the output is interpolated between them (30, 50 fps). An arm that swings
past a hip link can be clear of it at frames t and t + 1 and pass through it in between.
Between two frames of the same span every capsule is taken at the average of its two world
placements (end point and segment vector averaged): a point at parameter s of that capsule is
``(p_t(s) + p_t+1(s)) / 2``, so the distance of two averaged capsules has the exact gradient
``(J_t + J_t+1) / 2`` in the two frames' coordinates (closest points fixed, as in
:mod:`retarget.costs.self_clearance`). It is close to the capsules of the interpolated pose
(the chord of a swing instead of its arc: 5 mm for a 0.5 m arm turning 0.3 rad in a frame).

Only a pair that keeps its margin at both frames is kept apart halfway (a pair passing
through itself between them): where the frames' own term acts, the midpoint's gradient, the
same direction for both frames, can push the nearer frame's capsule into the other one (an
SMPL humanoid's hand driven 5 cm into its hip). Halfway it keeps its margin, or its distance
at the nearer frame less ``MIDPOINT_SLACK`` where that is less than 5 mm above the margin
(the chord's error).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.broad_phase import candidates
from retarget.capsules import segment_distance
from retarget.kinematics import Poses
from retarget.selfcollision import SelfClearance

MIDPOINT_SLACK = 0.005
"""Metres a pair may come closer halfway between two frames than at both of them."""


@dataclass
class MidpointPairs:
    """Pair entries (E) closer than their limit halfway between frames t and t + 1.

    Attributes:
        frame: (E,) t; pair: (E,) pair index; dist: (E,) signed distance (m) of the averaged
            capsules; limit: (E,) the distance the pair keeps there (m, see the module
            docstring): the entries are those with ``dist < limit``.
        pa, pb: (E, 3) world points of the first and second capsule at frame t whose averages
            are the closest points; pa_next, pb_next: (E, 3) the same points at frame t + 1.
    """

    frame: np.ndarray
    pair: np.ndarray
    dist: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    pa_next: np.ndarray
    pb_next: np.ndarray
    limit: np.ndarray


def _parameter(point: np.ndarray, start: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """(E,) parameter s in [0, 1] of ``point`` (E, 3) on the segments start + s vector (E, 3)."""
    length2 = np.einsum("ek,ek->e", vector, vector)
    s = np.einsum("ek,ek->e", point - start, vector) / np.maximum(length2, 1e-12)
    return np.clip(np.where(length2 > 1e-12, s, 0.0), 0.0, 1.0)


def midpoint_pairs(poses: Poses, sc: SelfClearance, coupled: np.ndarray) -> MidpointPairs:
    """The entries closer than their limit between the frames t and t + 1 where ``coupled``
    (T - 1,) bool is true (frames of one span), each capsule averaged over the two frames,
    of the pairs that keep their margin at both frames.

    Broad phase as :func:`retarget.selfcollision.close_pairs` (an averaged capsule's segment is
    no longer than the capsule's; its centre lies as close to its cluster's averaged sphere centre).
    """
    t = np.flatnonzero(coupled)
    rot, pos = poses.rot[:, sc.node], poses.pos[:, sc.node]
    start = pos + np.einsum("tcij,cj->tci", rot, sc.p0)  # (T, C, 3) world segments
    vector = np.einsum("tcij,cj->tci", rot, sc.segment)
    avg_start, avg_vector = 0.5 * (start[t] + start[t + 1]), 0.5 * (vector[t] + vector[t + 1])
    centre = avg_start + 0.5 * avg_vector
    clusters = sc.group_centres(poses)  # the cluster spheres averaged over the two frames as well
    cluster_centre = None if clusters is None else 0.5 * (clusters[t] + clusters[t + 1])
    fr, pr = candidates(sc.groups, centre, cluster_centre, sc.first, sc.second, sc.reach_squared)
    i, j = sc.first[pr], sc.second[pr]
    radii = sc.radius[i] + sc.radius[j]
    axis, pa, pb = segment_distance(avg_start[fr, i], avg_vector[fr, i], avg_start[fr, j], avg_vector[fr, j])
    near = axis - radii < sc.margin[pr]  # the limit is at most the margin
    fr, pr, i, j, radii = fr[near], pr[near], i[near], j[near], radii[near]
    s = _parameter(pa[near], avg_start[fr, i], avg_vector[fr, i])[:, None]
    u = _parameter(pb[near], avg_start[fr, j], avg_vector[fr, j])[:, None]
    dist = axis[near] - radii
    frame = t[fr]
    nxt = frame + 1
    at_t = segment_distance(start[frame, i], vector[frame, i], start[frame, j], vector[frame, j])[0]
    at_next = segment_distance(start[nxt, i], vector[nxt, i], start[nxt, j], vector[nxt, j])[0]
    ends = np.minimum(at_t, at_next) - radii
    limit = np.minimum(sc.margin[pr], ends - MIDPOINT_SLACK)
    keep = (dist < limit) & (ends >= sc.margin[pr])
    frame, pr, i, j, s, u = frame[keep], pr[keep], i[keep], j[keep], s[keep], u[keep]
    nxt = frame + 1
    return MidpointPairs(
        frame,
        pr,
        dist[keep],
        start[frame, i] + s * vector[frame, i],
        start[frame, j] + u * vector[frame, j],
        start[nxt, i] + s * vector[nxt, i],
        start[nxt, j] + u * vector[nxt, j],
        limit[keep],
    )
