"""The two-level broad phase of the self-clearance pairs finds every close entry.

A robot whose meshes are split into many convex pieces pairs hundreds of capsules per two
bodies (Digit with Shadow hands: 455,000 pairs); its pairs are tested only where the spheres
around clusters of their capsules come close. Checked here on G1's real tree with each capsule
split into pieces along its segment (12 pieces: several clusters per body): :func:`close_pairs`
must give exactly the entries that the full distance matrix puts within the margin, in the
same order.
"""

from __future__ import annotations

import numpy as np
import pytest

from retarget import load_robot
from retarget.broad_phase import CLUSTER
from retarget.selfcollision import SelfClearance, capsule_distances, close_pairs


def _split(sc: SelfClearance, pieces: int) -> SelfClearance:
    """``sc`` with each capsule cut into ``pieces`` along its segment, every piece of a pair's
    first capsule paired with every piece of its second."""
    s = np.linspace(0.0, 1.0, pieces + 1)
    seg = sc.p1 - sc.p0
    p0 = (sc.p0[:, None] + s[None, :-1, None] * seg[:, None]).reshape(-1, 3)
    p1 = (sc.p0[:, None] + s[None, 1:, None] * seg[:, None]).reshape(-1, 3)
    a = (sc.first[:, None] * pieces + np.arange(pieces)).repeat(pieces, axis=1).ravel()
    b = np.tile(sc.second[:, None] * pieces + np.arange(pieces), (1, pieces)).ravel()
    return SelfClearance(
        node=np.repeat(sc.node, pieces),
        p0=p0,
        p1=p1,
        radius=np.repeat(sc.radius, pieces),
        first=a,
        second=b,
        geom=np.repeat(sc.geom, pieces),
        margin=np.repeat(sc.margin, pieces * pieces) + 0.03,
    )


@pytest.fixture(scope="module")
def g1_poses():
    robot = load_robot("g1")
    rng = np.random.default_rng(3)
    lower, upper = np.clip(robot.lower, -np.pi, np.pi), np.clip(robot.upper, -np.pi, np.pi)
    n = 120
    q = rng.uniform(lower, upper, (n, len(lower)))
    return robot, robot.tree.forward(np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)), q)


@pytest.mark.parametrize("pieces", [6, 12])  # 12: more than CLUSTER per node, several spheres
def test_split_capsules_are_grouped_and_every_close_entry_found(g1_poses, pieces):
    robot, poses = g1_poses
    sc = robot.self_clearance
    assert sc is not None and sc.groups is None  # one capsule per geom: the one-level test
    split = _split(sc, pieces)
    groups = split.groups
    assert groups is not None
    if pieces > CLUSTER:  # every node several clusters
        assert len(groups.node) >= 2 * len(np.unique(split.node))
    assert len(groups.first) < split.num_pairs / 8
    dist, _, _ = capsule_distances(poses, split)  # (T, P): the reference
    frame, pair = np.nonzero(dist < split.margin)
    close = close_pairs(poses, split)
    assert frame.size > 1000  # random poses fold limbs into each other
    np.testing.assert_array_equal(close.frame, frame)
    np.testing.assert_array_equal(close.pair, pair)
    np.testing.assert_allclose(close.dist, dist[frame, pair], atol=1e-12)


def test_one_level_and_two_level_agree_on_the_robots_own_pairs(g1_poses):
    robot, poses = g1_poses
    sc = robot.self_clearance
    dist, _, _ = capsule_distances(poses, sc)
    frame, pair = np.nonzero(dist < sc.margin)
    close = close_pairs(poses, sc)
    np.testing.assert_array_equal(close.frame, frame)
    np.testing.assert_array_equal(close.pair, pair)
