"""Broad phase of the self-clearance pairs: which (frame, pair) entries may be within reach.

A pair of capsules may be within its margin only where the spheres around their segments
(midpoint, half length + radius) come within it: the pair's ``reach``. Testing every pair in
every frame costs (T, P); a robot whose meshes are split into many convex pieces (Digit with
Shadow hands: 1,103 collision geoms, 455,000 pairs) needs gigabytes for it. So each tree node's
capsules are gathered into clusters of at most ``CLUSTER`` (one sphere around their spheres,
riding on the node), the pairs grouped by the two clusters of their capsules, and only the
groups whose cluster spheres come within the group's largest reach get their pairs tested.
The test is conservative: every entry the one-level test finds, this one finds
(:func:`candidates` returns them in the same order). It pays where the groups hold many pairs
(Digit: about 33 each); a robot of one geom per body (G1: 302 pairs between 207 body pairs)
keeps the one-level test, which is faster there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GROUPED = 8
"""Mean pairs per group from which the two-level test is used (fewer: no groups)."""
CLUSTER = 8
"""Most capsules of one node in one sphere (a node with more gets several)."""


@dataclass(frozen=True)
class PairGroups:
    """Pairs (P) grouped by their capsules' clusters (G groups over N clusters).

    Attributes:
        node: (N,) the tree node each cluster rides on.
        centre: (N, 3) each cluster's sphere centre in its node's frame; radius: (N,) m,
            enclosing the spheres of its capsules.
        first, second: (G,) indices of each group's two clusters.
        reach: (G,) m, the cluster-sphere distance below which a pair of the group may be
            within its own reach.
        order: (P,) pair indices sorted by group; start: (G + 1,) each group's slice of it.
    """

    node: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    first: np.ndarray
    second: np.ndarray
    reach: np.ndarray
    order: np.ndarray
    start: np.ndarray


def pair_groups(
    node: np.ndarray,
    mid: np.ndarray,
    bound: np.ndarray,
    first: np.ndarray,
    second: np.ndarray,
    reach: np.ndarray,
) -> PairGroups | None:
    """Groups of the pairs ``first``, ``second`` (P,) of capsules on tree nodes ``node`` (C,),
    their sphere centres ``mid`` (C, 3) in the node frames and radii ``bound`` (C,), each pair
    within reach below a centre distance ``reach`` (P,) m: by the clusters of :func:`_clusters`.
    None where the groups would hold fewer than ``GROUPED`` pairs each."""
    node_pairs = len(np.unique(node[first] * (int(node.max(initial=0)) + 1) + node[second]))
    if len(first) < GROUPED * max(node_pairs, 1):  # the clusters' groups are at least as many
        return None
    cluster, used = _clusters(node, mid)
    centre = np.zeros((len(used), 3))
    radius = np.zeros(len(used))
    for n in range(len(used)):
        on = cluster == n
        lo, hi = (mid[on] - bound[on, None]).min(axis=0), (mid[on] + bound[on, None]).max(axis=0)
        centre[n] = 0.5 * (lo + hi)
        radius[n] = float(np.max(np.linalg.norm(mid[on] - centre[n], axis=1) + bound[on]))
    a, b = cluster[first], cluster[second]
    key = a * len(used) + b
    order = np.argsort(key, kind="stable")
    keys, start = np.unique(key[order], return_index=True)
    start = np.append(start, len(order))
    # A pair (i, j) of clusters (a, b) is within reach only if |c_a - c_b| < R_a + R_b + extra,
    # where |m_i - c_a| <= R_a - bound_i: extra = reach_ij - bound_i - bound_j at most.
    extra = reach - bound[first] - bound[second]
    group_extra = np.maximum.reduceat(extra[order], start[:-1]) if len(order) else np.zeros(0)
    ga, gb = keys // len(used), keys % len(used)
    if len(order) < GROUPED * max(len(keys), 1):
        return None
    return PairGroups(used, centre, radius, ga, gb, radius[ga] + radius[gb] + group_extra, order, start)


def _clusters(node: np.ndarray, mid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each node's capsules (C) cut into clusters of at most ``CLUSTER`` by halving them along
    their centres' principal direction: the cluster of each capsule (C,) and the node of each
    cluster (K,)."""
    cluster = np.zeros(len(node), dtype=int)
    nodes: list[int] = []

    def split(idx: np.ndarray) -> None:
        if len(idx) <= CLUSTER:
            cluster[idx] = len(nodes)
            nodes.append(int(node[idx[0]]))
            return
        spread = mid[idx] - mid[idx].mean(axis=0)
        axis = np.linalg.svd(spread, full_matrices=False)[2][0]
        order = idx[np.argsort(spread @ axis, kind="stable")]
        split(order[: len(order) // 2])
        split(order[len(order) // 2 :])

    for n in np.unique(node):
        split(np.flatnonzero(node == n))
    return cluster, np.array(nodes, dtype=int)


def candidates(
    groups: PairGroups | None,
    mid: np.ndarray,
    centre: np.ndarray | None,
    first: np.ndarray,
    second: np.ndarray,
    reach2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(frame, pair) entries (E,) whose capsule spheres come within the pair's reach, sorted
    by frame then pair.

    Args:
        groups: :func:`pair_groups` of the pairs (None: every pair is tested).
        mid: (T, C, 3) world centres of the capsules' spheres; centre: (T, N, 3) world
            centres of the cluster spheres in the same frames (None without groups).
        first, second: (P,) the pairs' capsules; reach2: (P,) their squared reach.
    """
    if groups is None or centre is None:
        d = mid[:, first] - mid[:, second]
        frame, pair = np.nonzero(np.einsum("tpk,tpk->tp", d, d) < reach2)
        return frame, pair
    diff = centre[:, groups.first] - centre[:, groups.second]
    gt, gg = np.nonzero(np.einsum("tgk,tgk->tg", diff, diff) < groups.reach**2)
    count = groups.start[gg + 1] - groups.start[gg]
    fr = np.repeat(gt, count)
    offset = np.arange(fr.size) - np.repeat(np.cumsum(count) - count, count)
    pr = groups.order[np.repeat(groups.start[gg], count) + offset]
    d = mid[fr, first[pr]] - mid[fr, second[pr]]
    near = np.einsum("ek,ek->e", d, d) < reach2[pr]
    fr, pr = fr[near], pr[near]
    sort = np.lexsort((pr, fr))
    return fr[sort], pr[sort]
