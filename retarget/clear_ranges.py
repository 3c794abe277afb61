"""Joint ranges the robot's own collision geometry allows: the trunk's, the knees' and elbows'.

A robot file may give its waist joints more range than its trunk's collision geoms leave free:
a small robot's chest and waist written as two boxes, one yawing and rolling below the other
(Stanford's ToddlerBot in GMR's assets), overlap 10 mm at a quarter of the waist roll's
range and 24 mm at its end, while the solver's capsules around those boxes, turned about their
own axis, never see it. Such a joint is kept where it leaves the robot clear:

:func:`trunk_ranges` sweeps each joint between the pelvis and the torso alone over its range
(``SWEEP_POINTS`` values, every other joint at rest) and measures the robot's geoms with
MuJoCo's own collision detection (its exclusions, contype/conaffinity and the parent-child
filter honoured); the range kept is the interval around the rest value in which no two
of the trunk's bodies overlap deeper than ``CLEAR_DEPTH`` (the arms and legs move with the
human and are kept clear by the solver; a hand hanging at rest beside a turning pelvis is not
the waist's limit). Where more than one joint is narrowed (a spine of two rolling links), the
ranges are shrunk together towards rest by one factor until every combination of their ends
and rest values is clear too. The inferred mapping (:mod:`retarget.automap`)
writes these as its ``ranges``, for the user to review.
"""

from __future__ import annotations

import itertools

import mujoco
import numpy as np

from retarget.anatomy import Anatomy
from retarget.robot_files import ancestors

SWEEP_POINTS = 49
"""Values of each trunk joint swept over its range."""
BISECTIONS = 10
"""Halvings of the factor that shrinks the narrowed ranges together."""
TOGETHER_MOST = 6
"""Most narrowed joints whose ends are checked in every combination (3^n poses); more keep
each its own interval."""
CLEAR_DEPTH = 0.002
"""Metres two of the robot's geoms may overlap in a swept pose (the solver's own tolerance,
:data:`retarget.selfcollision.SWEEP_DEPTH`); ``controlmm validate`` fails 5 mm."""


def trunk_bodies(a: Anatomy) -> list[int]:
    """The pelvis, the torso and the bodies between them (either may sit above the other),
    their common ancestor last; empty without a torso."""
    if a.torso is None:
        return []
    up_pelvis, up_torso = ancestors(a.model, a.pelvis), ancestors(a.model, a.torso)
    common = next(b for b in up_pelvis if b in up_torso)
    return up_pelvis[: up_pelvis.index(common)] + up_torso[: up_torso.index(common)] + [common]


def trunk_joints(a: Anatomy) -> list[int]:
    """MuJoCo ids of the limited hinge joints of the trunk's bodies (:func:`trunk_bodies`),
    the common ancestor's own excluded."""
    bodies = trunk_bodies(a)[:-1]
    m = a.model
    return [
        j
        for b in bodies
        for j in range(int(m.body_jntadr[b]), int(m.body_jntadr[b] + m.body_jntnum[b]))
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and m.jnt_limited[j]
    ]


def _deepest(
    model: mujoco.MjModel, data: mujoco.MjData, trunk: np.ndarray, other: np.ndarray | None = None
) -> float:
    """Deepest overlap (m, 0 for none) of two of the trunk's bodies (``trunk``: (nbody,) bool)
    in ``data``'s pose; with ``other`` ((nbody,) bool), of a trunk body and an other one."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    n = data.ncon
    if not n:
        return 0.0
    geoms = data.contact.geom[:n]
    bodies = model.geom_bodyid[geoms]
    if other is None:
        ours = trunk[bodies[:, 0]] & trunk[bodies[:, 1]] & (bodies[:, 0] != bodies[:, 1])
    else:
        ours = (trunk[bodies[:, 0]] & other[bodies[:, 1]]) | (other[bodies[:, 0]] & trunk[bodies[:, 1]])
    dist = data.contact.dist[:n][ours]
    return float(max(0.0, -dist.min())) if dist.size else 0.0


def _clear_interval(
    m: mujoco.MjModel, data: mujoco.MjData, j: int, bodies: np.ndarray, other: np.ndarray | None = None
) -> tuple[float, float, float] | None:
    """(lower, rest, upper): the interval of joint ``j``'s range around its rest value in
    which, swept alone (every other joint at rest), no two of ``bodies`` ((nbody,) bool; with
    ``other``, none of them and one of ``other``) overlap deeper than CLEAR_DEPTH; None where
    the whole range is clear or the rest is not."""
    adr = int(m.jnt_qposadr[j])
    lo, hi = (float(v) for v in m.jnt_range[j])
    rest = float(np.clip(m.qpos0[adr], lo, hi))
    values = np.unique(np.r_[np.linspace(lo, hi, SWEEP_POINTS), rest])
    ok = np.empty(len(values), dtype=bool)
    for k, v in enumerate(values):
        data.qpos[:] = m.qpos0
        data.qpos[adr] = v
        ok[k] = _deepest(m, data, bodies, other) <= CLEAR_DEPTH
    at = int(np.flatnonzero(values == rest)[0])
    if not ok[at] or ok.all():
        return None
    first = at
    while first > 0 and ok[first - 1]:
        first -= 1
    last = at
    while last < len(values) - 1 and ok[last + 1]:
        last += 1
    return float(values[first]), rest, float(values[last])


def clear_ranges(a: Anatomy) -> dict[str, tuple[float, float]]:
    """Joint name -> (lower, upper) rad: :func:`trunk_ranges`, :func:`middle_ranges` and
    :func:`wrist_ranges`."""
    return {**trunk_ranges(a), **middle_ranges(a), **wrist_ranges(a)}


def wrist_ranges(a: Anatomy) -> dict[str, tuple[float, float]]:
    """Joint name -> (lower, upper) rad for each named wrist joint (an arm's joints on the
    bodies past its forearm, the elbow's body) that, swept alone, folds the hand (those
    bodies) into the forearm within its range: the interval around rest where they stay
    clear, shrunk together until every combination of their ends is clear too. An SMPL
    humanoid's wrist, three hinges of +-180 degrees, folds its hand's box 10 mm into its
    forearm's capsule at 130 degrees. Fingers meeting each other or a thumb are the solver's
    (a hand's branching links are kept apart), not a range's."""
    m = a.model
    data = mujoco.MjData(m)
    out: dict[str, tuple[float, float]] = {}
    for arm in a.arms.values():
        hand = [b for b in range(m.nbody) if arm.middle_body in ancestors(m, b) and b != arm.middle_body]
        if not hand:
            continue
        forearm, bodies = np.zeros(m.nbody, dtype=bool), np.zeros(m.nbody, dtype=bool)
        forearm[arm.middle_body], bodies[hand] = True, True
        joints = [
            j
            for b in hand
            for j in range(int(m.body_jntadr[b]), int(m.body_jntadr[b] + m.body_jntnum[b]))
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and m.jnt_limited[j] and m.joint(j).name
        ]
        out |= _narrowed_together(m, data, joints, forearm, bodies)
    return out


def middle_ranges(a: Anatomy) -> dict[str, tuple[float, float]]:
    """Joint name -> (lower, upper) rad for each named knee and elbow joint that, swept alone,
    folds its limb's own links into each other within its range (a knee bent past 130 degrees
    pressing the shin into the hip's links): the interval around rest where they stay clear.
    The body the limb hangs from does not count (an elbow bending a hanging arm's forearm into
    the belly is the arm's pose, not the elbow's limit)."""
    m = a.model
    data = mujoco.MjData(m)
    out: dict[str, tuple[float, float]] = {}
    for limb in [*a.legs.values(), *a.arms.values()]:
        j = limb.middle_joint
        if j is None or not m.joint(j).name or not m.jnt_limited[j]:
            continue
        if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        bodies = np.zeros(m.nbody, dtype=bool)
        bodies[list(limb.bodies)] = True
        bodies |= np.array([limb.end_body in ancestors(m, b) for b in range(m.nbody)])
        found = _clear_interval(m, data, j, bodies)
        if found is not None:
            out[m.joint(j).name] = (found[0], found[2])
    return out


def trunk_ranges(a: Anatomy) -> dict[str, tuple[float, float]]:
    """Joint name -> (lower, upper) rad for each named trunk joint (:func:`trunk_joints`)
    whose range the robot's geoms do not leave clear (see the module docstring)."""
    m = a.model
    trunk = np.zeros(m.nbody, dtype=bool)
    trunk[trunk_bodies(a)] = True
    joints = [j for j in trunk_joints(a) if m.joint(j).name]
    return _narrowed_together(m, mujoco.MjData(m), joints, trunk)


def _narrowed_together(
    m: mujoco.MjModel,
    data: mujoco.MjData,
    joints: list[int],
    bodies: np.ndarray,
    other: np.ndarray | None = None,
) -> dict[str, tuple[float, float]]:
    """Joint name -> (lower, upper) rad for each of ``joints`` whose range, swept alone, lets
    two of ``bodies`` ((nbody,) bool; with ``other``, one of them and one of ``other``) overlap
    (:func:`_clear_interval`). Each alone clear, they may not be together (a spine of two
    rolling links): the ranges shrink towards rest by one factor until every combination of
    their ends and rest values is clear (up to ``TOGETHER_MOST`` joints)."""

    def clear(adr: list[int], values: np.ndarray) -> bool:
        data.qpos[:] = m.qpos0
        data.qpos[adr] = values
        return _deepest(m, data, bodies, other) <= CLEAR_DEPTH

    narrowed: dict[int, tuple[float, float, float]] = {}  # qpos address -> (lower, rest, upper)
    names: dict[int, str] = {}
    for j in joints:
        found = _clear_interval(m, data, j, bodies, other)
        if found is not None:
            narrowed[int(m.jnt_qposadr[j])] = found
            names[int(m.jnt_qposadr[j])] = m.joint(j).name
    if not narrowed:
        return {}
    if len(narrowed) > TOGETHER_MOST:  # 3^n poses: each keeps its own interval
        return {names[k]: (lw, hg) for k, (lw, _, hg) in narrowed.items()}
    adr = list(narrowed)
    lo, rest, hi = (np.array(v) for v in zip(*narrowed.values(), strict=True))
    corners = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=len(adr))))  # (3^n, n)

    def poses(f: float) -> np.ndarray:
        return rest + np.where(corners < 0, f * (lo - rest), f * (hi - rest)) * np.abs(corners)

    factor = 1.0
    if not all(clear(adr, q) for q in poses(1.0)):
        low, high = 0.0, 1.0
        for _ in range(BISECTIONS):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if all(clear(adr, q) for q in poses(mid)) else (low, mid)
        factor = low
    return {
        names[k]: (r + factor * (lw - r), r + factor * (hg - r))
        for k, lw, r, hg in zip(adr, lo, rest, hi, strict=True)
    }
