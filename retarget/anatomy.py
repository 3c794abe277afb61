"""The anatomy of a humanoid MJCF, read from its kinematic tree and geometry (never its names).

:func:`find_anatomy` finds the pelvis, torso, head, two legs and two arms of a floating-base
model in its rest pose (``qpos0`` with the floating base in its rest orientation,
:func:`retarget.rest_frame.rest_root_quat`), in MuJoCo's convention: +Z up, the robot facing
+X, so its left is +Y.

1. **Feet**: on each side of the sagittal plane (the root's y), the body owning the lowest
   collision geom, or the link above it where that link stands on the floor too (a toe link
   below the foot). **Pelvis**: the feet's lowest common ancestor; a **leg** is the chain of
   bodies from the pelvis down to a foot.
2. **Arms**: the ends of the other jointed chains that lie clearly to one side (the head's
   chain stays near the midline) and reach at least half as far as that side's farthest end
   (not a crank beside the torso); per side, the common ancestor of those ends is the hand
   (a hand with fingers has several ends). **Torso**: the hands' common ancestor. Robots whose
   only chains are the legs have no arms (a legs-only robot retargets pelvis and legs). Arms
   whose geometry reaches the floor in the rest pose are a quadruped's: refused.
3. **Head**: the highest other jointed end near the midline, or the common ancestor of those
   as high (two eyes on joints of their own); else the head is part of the torso.
4. **Joints of a limb** (:func:`limb_anatomy`): the middle joint (knee / elbow) is the hinge
   past the first quarter of the limb whose axis crosses the limb; the joints before it form the
   hip / shoulder, the joints after it the ankle / wrist. Each group's centre is the point
   nearest to its joint axes (a hip's three axes meet near one point). Ball joints written as
   hinges at one point (SMPL humanoids): hinges at the knee's point are the knee's, the hip /
   shoulder is the last ball before the knee (a clavicle before it: ``Limb.before``) and the
   ankle / wrist the first after it (a hand past it: ``Limb.beyond``). A hinge right after
   the knee and parallel to it, nearer to it than to the ankle, is the rest of a rolling knee
   (Draco3's); a knee / elbow anchored far out along its own axis is read on the limb's line
   (``MIDDLE_OFF_LINE``), and the limb is measured from where its first two axes pass nearest
   each other where its first joint is anchored far from there (:func:`_limb_start`). A leg
   with nothing jointed past its knee ends in a point foot: its ankle is the leg's tip.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from controlmm.errors import ControlMMError
from retarget.geoms import aabb_corners, geom_points
from retarget.human import HUMAN_FOREARM, HUMAN_HALF_HAND, HUMAN_UPPER_ARM
from retarget.kinematics import axes_centre
from retarget.rest_frame import rest_root_quat
from retarget.robot_files import ancestors, free_root, jointed_link, welded_below

MIDDLE_RANGE = (0.25, 0.85)
"""Fraction of a limb's length (from its start, :func:`_limb_start`, to its tip) where its knee /
elbow may sit."""
MIDDLE_OFF_LINE = 0.05
"""A knee / elbow anchor further than this (m) along its own axis from the limb's line (hip to
ankle, shoulder to wrist) is moved onto the point of the axis nearest that line: a URDF may put
the joint's link origin anywhere on its axis (THORMANG3's knees 9.3 cm outboard of its legs)."""
ACROSS = 0.6
"""A middle joint's axis crosses the limb: |cos| to the limb's direction below this."""
ALONG = 0.1
"""A twist hinge's axis runs along the limb: |cos| to the limb's direction (first joint to tip)
above 1 - this."""
HEAD_LEVEL = 0.02
"""Ends near the midline above the shoulders within this fraction of the robot's height of the
highest one are one head's (two eyes): the head is their common ancestor."""
SIDE_FRACTION = 0.3
"""A chain end belongs to an arm when it lies further from the midline than this fraction of
the furthest such end; nearer ends are the head's (or other midline parts)."""
ARM_REACH = 0.5
"""...and when it lies at least this fraction as far from where the two sides' ends branch
(their common ancestor's origin) as the farthest end on its side: a short link beside the
torso (LimX HU_D03's waist cranks, one hinge each, about 11 cm from there against the hands'
29 cm) is not a hand."""
WRIST_SHARE = HUMAN_FOREARM / (HUMAN_FOREARM + HUMAN_HALF_HAND)
"""Where the wrist of an arm without wrist joints sits between its elbow (0) and its tip (1):
the human forearm against the forearm plus half a hand."""
FEET_LEVEL = 0.05
"""The two feet's lowest points lie within this fraction of the robot's height of each other."""
SAME_ANCHOR = 1e-3
"""Hinges whose anchors are this close (m) act at one point (a ball joint written as hinges)."""
SOLE_BAND = 0.015
"""A link whose collision geometry comes this close (fraction of the robot's height) to the
floor in the rest pose stands on it: the foot above a toe link is the foot."""
BARE_FOOT = 0.005
"""A jointed link below a foot whose origin lies this much (m) lower than the foot's lowest
collision point: the leg goes on below its geometry (feet without collision geoms)."""
ARM_ABOVE_FLOOR = 0.15
"""An arm whose collision geometry comes nearer the floor than this fraction of the robot's
height in the rest pose stands on it: four limbs on the floor are a quadruped's."""

_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


@dataclass(frozen=True)
class Limb:
    """One leg or arm in the rest pose (world frame, metres).

    Attributes:
        side: ``"left"`` (+Y) or ``"right"``.
        bodies: the chain's bodies from below its branch body to its end (foot / hand).
        joints: its hinge and slide joints, root to end.
        middle_joint: the knee / elbow joint, or None (a limb without one).
        root_body, middle_body, end_body: the bodies carrying the hip / shoulder centre (the
            body after the root group's joints), the knee / elbow and the foot / hand.
        root, middle, end: (3,) the hip / shoulder centre, the knee / elbow centre and the
            ankle / wrist centre.
        tip: (3,) the limb's far end (the lowest sole point of a leg, a hand's farthest point).
        beyond: the joints past the ankle / wrist where that is a ball joint written as
            hinges at one point (an SMPL humanoid's hand joints past its wrist's).
        before: the joints before the hip / shoulder where that is such a ball joint (a
            clavicle's).
    """

    side: str
    bodies: tuple[int, ...]
    joints: tuple[int, ...]
    middle_joint: int | None
    root_body: int
    middle_body: int
    end_body: int
    root: np.ndarray
    middle: np.ndarray
    end: np.ndarray
    tip: np.ndarray
    beyond: tuple[int, ...] = ()
    before: tuple[int, ...] = ()

    @property
    def end_joints(self) -> tuple[int, ...]:
        """The ankle / wrist joints (after the middle joint)."""
        if self.middle_joint is None:
            return ()
        return self.joints[self.joints.index(self.middle_joint) + 1 :]


@dataclass(frozen=True)
class Anatomy:
    """What :func:`find_anatomy` found, in the rest pose.

    Attributes:
        model: the compiled model; root: the floating-base body.
        pelvis: the legs' common ancestor; torso: the arms' (None without arms); head: the
            head's end body (None: the head is part of the torso).
        legs, arms: ``{"left": Limb, "right": Limb}`` (arms empty for a legs-only robot).
        xpos: (nbody, 3), xmat: (nbody, 3, 3) rest body poses (root at its qpos0 position,
            in its rest orientation: facing +X).
        floor_z: the lowest collision point (m); top_z: the highest point of any geom's
            bounding box (m).
    """

    model: mujoco.MjModel
    root: int
    pelvis: int
    torso: int | None
    head: int | None
    legs: dict[str, Limb]
    arms: dict[str, Limb]
    xpos: np.ndarray
    xmat: np.ndarray
    floor_z: float
    top_z: float

    @property
    def height(self) -> float:
        """Standing height (m): the highest geom point above the soles in the rest pose."""
        return self.top_z - self.floor_z

    def local(self, body: int, point: np.ndarray) -> np.ndarray:
        """A rest-pose world point (3,) in the frame of ``body``."""
        return self.xmat[body].T @ (np.asarray(point, dtype=float) - self.xpos[body])


def _rest_data(model: mujoco.MjModel, root: int) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    free = next(j for j in range(model.njnt) if model.jnt_bodyid[j] == root)
    adr = int(model.jnt_qposadr[free])
    data.qpos[adr + 3 : adr + 7] = rest_root_quat(model, root)
    mujoco.mj_kinematics(model, data)
    return data


def _geom_world_points(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Support points (P, 3) of geom ``g`` in the world and their radii (P,)."""
    pts, rad = geom_points(model, g)
    body = int(model.geom_bodyid[g])
    return data.xpos[body] + pts @ data.xmat[body].reshape(3, 3).T, rad


def common_ancestor(model: mujoco.MjModel, bodies: list[int]) -> int:
    """The deepest body that is an ancestor of (or equal to) every body of ``bodies``."""
    chains = [ancestors(model, b)[::-1] for b in bodies]
    out = 0
    for level in zip(*chains, strict=False):
        if len(set(level)) != 1:
            break
        out = level[0]
    return out


def chain(model: mujoco.MjModel, top: int, end: int) -> tuple[int, ...]:
    """The bodies below ``top`` down to ``end`` (``end`` a descendant of ``top``), top first."""
    return tuple(b for b in ancestors(model, end) if b != top and top in ancestors(model, b))[::-1]


def _chain_joints(model: mujoco.MjModel, bodies: tuple[int, ...]) -> tuple[int, ...]:
    return tuple(
        j
        for b in bodies
        for j in range(model.njnt)
        if model.jnt_bodyid[j] == b and model.jnt_type[j] in _HINGE_SLIDE
    )


def limb_anatomy(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    side: str,
    bodies: tuple[int, ...],
    tip: np.ndarray,
) -> Limb:
    """Hip / knee / ankle (or shoulder / elbow / wrist) of the chain ``bodies`` reaching ``tip`` (3,).

    Without a joint after the middle one the ankle / wrist centre is the end body's origin, or
    ``tip`` where that body is the middle joint's own (a point foot at the end of the shank:
    ODRI's Bolt had its ankle at its knee).
    """
    joints = _chain_joints(model, bodies)
    anchors = np.array([data.xanchor[j] for j in joints]).reshape(-1, 3)
    axes = np.array([data.xaxis[j] for j in joints]).reshape(-1, 3)
    start = _limb_start(anchors, axes)
    length = max(float(np.linalg.norm(tip - start)), 1e-6)
    # The first hinge past the hip / shoulder whose axis crosses the limb (a twist joint's
    # axis runs along it), or the next one past the upper arm's twist (_after_upper_twist);
    # else the hinge nearest the middle.
    best, best_score, across = None, np.inf, []
    for i in range(1, len(joints)):
        if model.jnt_type[joints[i]] != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        out = anchors[i] - start
        frac = float(np.linalg.norm(out)) / length
        if not MIDDLE_RANGE[0] <= frac <= MIDDLE_RANGE[1]:
            continue
        cos = abs(float(axes[i] @ out)) / max(float(np.linalg.norm(out)), 1e-9)
        if cos < ACROSS:
            across.append(i)
        elif not across and abs(frac - 0.5) < best_score:
            best, best_score = i, abs(frac - 0.5)
    if across:
        best = _after_upper_twist(model, joints, anchors, axes, start, length, tip, across)
    end_body = bodies[-1]
    if best is None:
        middle_joint, middle_body = None, bodies[len(bodies) // 2]
        middle = data.xpos[middle_body].copy()
        root_idx = list(range(len(joints)))
        end_idx: list[int] = []
    else:
        middle_joint = joints[best]
        middle_body = int(model.jnt_bodyid[middle_joint])
        middle = anchors[best].copy()
        # Hinges sharing the middle joint's anchor are the rest of a ball-like knee / elbow
        # (SMPL humanoids' three-hinge knees and elbows), not the hip / ankle.
        apart = [i for i in range(len(joints)) if np.linalg.norm(anchors[i] - middle) > SAME_ANCHOR]
        root_idx = [i for i in apart if i < best]
        end_idx = [i for i in apart if i > best]
        # A rolling knee written as two parallel hinges (Draco3's): a hinge right after the
        # middle one, parallel to it and nearer to it than to the limb's last joint, is the
        # knee's too, and the knee's point is halfway between them.
        rolling = [
            i
            for i in end_idx[:1]
            if abs(float(axes[i] @ axes[best])) > 1.0 - 1e-3
            and np.linalg.norm(anchors[i] - middle) < np.linalg.norm(anchors[i] - anchors[end_idx[-1]])
        ]
        if rolling:
            middle = (middle + anchors[rolling[0]]) / 2
            end_idx = end_idx[1:]
    root_body = int(model.jnt_bodyid[joints[root_idx[-1]]]) if root_idx else bodies[0]
    if best is not None and root_body == middle_body:  # hip and knee on one body: keep the thigh's
        root_body = int(model.body_parentid[middle_body])
    # A ball joint written as hinges at one point is the hip / shoulder (the last such group
    # before the middle: a clavicle's joints come before it) or the ankle / wrist (the first
    # after it: a hand's joints come after it); otherwise the centre of all the group's axes.
    root_groups, end_groups = _same_anchor(root_idx, anchors), _same_anchor(end_idx, anchors)
    before: list[int] = []
    if root_groups and len(root_groups[-1]) > 1:
        root_idx, before = root_groups[-1], [i for g in root_groups[:-1] for i in g]
    beyond: list[int] = []
    if end_groups and len(end_groups[0]) > 1:
        end_idx, beyond = end_groups[0], [i for g in end_groups[1:] for i in g]
    root = axes_centre(anchors[root_idx], axes[root_idx]) if root_idx else data.xpos[bodies[0]].copy()
    if end_idx:
        centre = axes_centre(anchors[end_idx], axes[end_idx])
    elif best is not None and end_body == middle_body:  # nothing past the knee: a point foot
        centre = np.asarray(tip, dtype=float).copy()
    else:
        centre = data.xpos[end_body].copy()
    if best is not None:  # a knee / elbow anchor far out along its own axis (a URDF link origin)
        on_line = _nearest_on_axis(middle, axes[best], root, centre)
        if np.linalg.norm(on_line - middle) > MIDDLE_OFF_LINE:
            middle = on_line
    return Limb(
        side,
        bodies,
        joints,
        middle_joint,
        root_body,
        middle_body,
        end_body,
        root,
        middle,
        centre,
        tip,
        tuple(joints[i] for i in beyond),
        tuple(joints[i] for i in before),
    )


def _limb_start(anchors: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(3,) where a limb's length is measured from: its first joint's anchor, or, where that lies
    further than MIDDLE_OFF_LINE along its axis from the point nearest the second joint's axis,
    that point (REEM-C's tilted shoulder joints anchored on the torso's midline, 21.7 cm in from
    the shoulder: its shoulder roll was taken for the elbow)."""
    start = anchors[0]
    if len(anchors) < 2 or abs(float(axes[0] @ axes[1])) > 1.0 - 1e-3:
        return start
    crossing = _nearest_on_axis(start, axes[0], anchors[1], anchors[1] + axes[1])
    return crossing if np.linalg.norm(crossing - start) > MIDDLE_OFF_LINE else start


def _nearest_on_axis(anchor: np.ndarray, axis: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(3,) the point of the line through ``anchor`` along ``axis`` nearest the line from
    ``start`` to ``end`` (``anchor`` itself where the two are parallel)."""
    d, w = end - start, anchor - start
    a, b, c = float(axis @ axis), float(axis @ d), float(d @ d)
    den = a * c - b * b
    if den <= 1e-9 * a * c:
        return anchor.copy()
    return anchor + (b * float(d @ w) - c * float(axis @ w)) / den * axis


def _after_upper_twist(
    model: mujoco.MjModel,
    joints: tuple[int, ...],
    anchors: np.ndarray,
    axes: np.ndarray,
    start: np.ndarray,
    length: float,
    tip: np.ndarray,
    across: list[int],
) -> int:
    """Of the hinges across the limb (``across``: indices into ``joints``, in order), the
    knee / elbow: the first, unless no twist (a hinge along the limb, not at its start) comes
    before it, one follows it, and the next one across past that twist sits nearer the limb's middle; then
    that one. Atlas's clavicle joint sits 25 cm above its shoulder-roll hinge, so that hinge
    comes a third of the way along the arm, before the upper arm's twist and the elbow."""
    direction = (tip - start) / length
    hinge = [model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE for j in joints]
    twists = [i for i in range(len(joints)) if hinge[i] and abs(float(axes[i] @ direction)) >= 1.0 - ALONG]
    first = across[0]
    # A twist where the limb starts turns the whole limb (loco-mujoco's Atlas: its clavicle's
    # yaw, vertical with the arm hanging), not the upper arm below the shoulder.
    if any(t < first and np.linalg.norm(anchors[t] - start) > SAME_ANCHOR for t in twists):
        return first
    twist = next((t for t in twists if t > first), None)
    if twist is None:
        return first
    later = [i for i in across if i > twist and np.linalg.norm(anchors[i] - anchors[twist]) > SAME_ANCHOR]
    if not later:
        return first
    off_middle = [abs(float(np.linalg.norm(anchors[i] - start)) / length - 0.5) for i in (first, later[0])]
    return later[0] if off_middle[1] < off_middle[0] else first


def _same_anchor(idx: list[int], anchors: np.ndarray) -> list[list[int]]:
    """``idx`` split into runs of joints whose anchors coincide (within SAME_ANCHOR)."""
    groups: list[list[int]] = []
    for i in idx:
        if groups and np.linalg.norm(anchors[i] - anchors[groups[-1][-1]]) <= SAME_ANCHOR:
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def _robot_bodies(model: mujoco.MjModel, root: int) -> list[int]:
    return [b for b in range(1, model.nbody) if model.body_rootid[b] == root]


def _jointed_ends(model: mujoco.MjModel, bodies: list[int]) -> list[int]:
    """Bodies with a joint and no jointed body below them (the tips of the jointed chains)."""
    has_joint = np.zeros(model.nbody, dtype=bool)
    for j in range(model.njnt):
        if model.jnt_type[j] in _HINGE_SLIDE:
            has_joint[model.jnt_bodyid[j]] = True
    below = np.zeros(model.nbody, dtype=bool)  # a jointed body somewhere below
    for b in sorted(bodies, reverse=True):  # children have larger ids than their parents
        p = int(model.body_parentid[b])
        if has_joint[b] or below[b]:
            below[p] = True
    return [b for b in bodies if has_joint[b] and not below[b]]


def _foot_above_toes(
    model: mujoco.MjModel, body: int, root: int, low: dict[int, tuple[float, float]], sole_z: float
) -> int:
    """The highest of ``body`` and its ancestors (below ``root``) that each own a collision geom
    reaching below ``sole_z``: the CMU humanoid stands on its toe links and on the foot above them."""
    while True:
        parent = int(model.body_parentid[body])
        if parent in (0, root) or not any(
            model.geom_bodyid[g] == parent and z < sole_z for g, (z, _) in low.items()
        ):
            return body
        body = parent


def _bare_link_below(model: mujoco.MjModel, data: mujoco.MjData, foot: int, lowest: float) -> int | None:
    """A jointed link below ``foot`` whose origin lies ``BARE_FOOT`` lower than ``lowest`` (the
    foot's lowest collision point, m, world z in the rest pose ``data``); None without one (a toe
    joint sits above the sole)."""
    for b in range(foot + 1, model.nbody):
        if model.body_jntnum[b] and foot in ancestors(model, b) and data.xpos[b][2] < lowest - BARE_FOOT:
            return b
    return None


def _subtree(model: mujoco.MjModel, body: int, bodies: list[int]) -> list[int]:
    return [b for b in bodies if body in ancestors(model, b)]


def find_anatomy(model: mujoco.MjModel, name: str = "the robot") -> Anatomy:
    """The anatomy of a floating-base humanoid ``model`` (see the module docstring).

    Raises:
        ControlMMError: one line naming what is missing: no floating base, no collision
            geometry, no two legs (two feet on either side of the midline); or arms that
            reach the floor (a quadruped).
    """
    root = free_root(model)
    if root is None:
        raise ControlMMError(
            f"{name} has no free joint on a body of the world: a humanoid needs a floating base"
        )
    data = _rest_data(model, root)
    bodies = _robot_bodies(model, root)
    geoms = [
        g
        for g in range(model.ngeom)
        if model.body_rootid[model.geom_bodyid[g]] == root
        and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]
    if not geoms:
        raise ControlMMError(
            f"{name} has no collision geometry (no geom with contype/conaffinity, none in group 3): "
            "the feet must have some to stand on"
        )
    low = {}
    for g in geoms:
        pts, rad = _geom_world_points(model, data, g)
        if len(pts):
            low[g] = (float((pts[:, 2] - rad).min()), float(data.geom_xpos[g][1] - data.xpos[root][1]))
    tops = []
    for g in range(model.ngeom):
        body = int(model.geom_bodyid[g])
        if model.body_rootid[body] == root:
            corners = data.xpos[body] + aabb_corners(model, g) @ data.xmat[body].reshape(3, 3).T
            tops.append(float(corners[:, 2].max()))
    floor_z = min(v[0] for v in low.values())
    top_z = max(tops) if tops else floor_z
    height = max(top_z - floor_z, 1e-3)
    feet: dict[str, int] = {}
    feet_z: dict[str, float] = {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        side_geoms = [g for g, (_, y) in low.items() if sign * y > 1e-3]
        if side_geoms:
            g = min(side_geoms, key=lambda g: low[g][0])
            feet[side], feet_z[side] = int(model.geom_bodyid[g]), low[g][0]
    if len(feet) < 2:
        raise ControlMMError(
            f"{name} has no two legs: no pair of feet (collision geoms at the bottom of the robot, one "
            "on each side of its midline, +Y left)"
        )
    if abs(feet_z["left"] - feet_z["right"]) > FEET_LEVEL * height:
        raise ControlMMError(
            f"{name} has no two legs standing level: the lowest collision geoms left and right of its "
            f"midline (on {model.body(feet['left']).name} and {model.body(feet['right']).name}) are "
            f"{100 * abs(feet_z['left'] - feet_z['right']):.1f} cm apart in height; at most "
            f"{100 * FEET_LEVEL * height:.1f} cm ({FEET_LEVEL:.0%} of its height) is allowed"
        )
    for side in feet:  # a toe link below the foot: the foot is the link its sole is on
        link = jointed_link(model, feet[side])  # the foot, not a cleat welded below it
        feet[side] = _foot_above_toes(model, link, root, low, floor_z + SOLE_BAND * height)
        bare = _bare_link_below(model, data, feet[side], feet_z[side])
        if bare is not None:
            raise ControlMMError(
                f"{name} has a {side} leg that goes on below its collision geometry: link "
                f"'{model.body(bare).name}' lies {100 * (feet_z[side] - data.xpos[bare][2]):.1f} cm lower "
                f"than the lowest geom of '{model.body(feet[side]).name}' and has none to stand on "
                "(give the foot a collision geom)"
            )
    pelvis = common_ancestor(model, [feet["left"], feet["right"]])
    if pelvis in (feet["left"], feet["right"]) or pelvis == 0:
        raise ControlMMError(f"{name} has no two legs: its feet are not on two separate chains")
    legs = {}
    for side in ("left", "right"):
        leg_bodies = chain(model, pelvis, feet[side])
        if len(_chain_joints(model, leg_bodies)) < 2:
            raise ControlMMError(f"{name} has no two legs: the {side} leg has fewer than 2 joints")
        tip = data.xpos[feet[side]].copy()
        tip[2] = feet_z[side]
        legs[side] = limb_anatomy(model, data, side, leg_bodies, tip)
    # Arms and head: the other jointed chains.
    leg_set = {b for limb in legs.values() for b in limb.bodies}
    ends = [
        e for e in _jointed_ends(model, bodies) if e not in leg_set and not leg_set & set(ancestors(model, e))
    ]
    lateral = {e: float(data.xpos[e][1] - data.xpos[root][1]) for e in ends}
    reach = max((abs(v) for v in lateral.values()), default=0.0)
    arms: dict[str, Limb] = {}
    torso = None
    sided = {
        side: [e for e in ends if sign * lateral[e] > SIDE_FRACTION * reach and reach > 1e-3]
        for side, sign in (("left", 1.0), ("right", -1.0))
    }
    if sided["left"] and sided["right"]:
        branch = data.xpos[common_ancestor(model, sided["left"] + sided["right"])]
        for side, side_ends in sided.items():
            far = {e: float(np.linalg.norm(data.xpos[e] - branch)) for e in side_ends}
            sided[side] = [e for e in side_ends if far[e] >= ARM_REACH * max(far.values())]
        hands = {side: common_ancestor(model, sided[side]) for side in sided}
        torso = common_ancestor(model, list(hands.values()))
        for side, hand in hands.items():
            arm_bodies = chain(model, torso, hand)
            if torso == 0 or len(_chain_joints(model, arm_bodies)) < 2:
                arms, torso = {}, None
                break
            arms[side] = _arm(model, data, side, arm_bodies, _subtree(model, hand, bodies))
    for side, limb in arms.items():
        arm = set(_subtree(model, limb.bodies[0], bodies))
        reach_down = [low[g][0] - floor_z for g in low if int(model.geom_bodyid[g]) in arm]
        if reach_down and min(reach_down) < ARM_ABOVE_FLOOR * height:
            raise ControlMMError(
                f"{name} stands on four limbs: its {side} arm ('{model.body(limb.bodies[-1]).name}') "
                f"comes within {100 * min(reach_down):.1f} cm of the floor in the rest pose, where a "
                f"humanoid's hands stay above {ARM_ABOVE_FLOOR:.0%} of its height (a quadruped?)"
            )
    arm_set = {b for limb in arms.values() for b in limb.bodies}
    shoulder_z = np.mean([a.root[2] for a in arms.values()]) if arms else -np.inf
    heads = [e for e in ends if e not in arm_set and not arm_set & set(ancestors(model, e))]
    heads = [
        e
        for e in heads
        if data.xpos[e][2] > shoulder_z and abs(lateral[e]) <= SIDE_FRACTION * max(reach, 1e-3)
    ]
    head = max(heads, key=lambda e: data.xpos[e][2]) if heads and arms else None
    if head is not None:  # two eyes on their own joints (Romeo's): the head is the link they hang from
        level = [e for e in heads if data.xpos[head][2] - data.xpos[e][2] <= HEAD_LEVEL * height]
        common = common_ancestor(model, level)
        if len(level) > 1 and common != torso and torso in ancestors(model, common):
            head = common
    return Anatomy(
        model=model,
        root=root,
        pelvis=pelvis,
        torso=torso,
        head=head,
        legs=legs,
        arms=arms,
        xpos=data.xpos.copy(),
        xmat=data.xmat.reshape(-1, 3, 3).copy(),
        floor_z=floor_z,
        top_z=top_z,
    )


def _arm(
    model: mujoco.MjModel, data: mujoco.MjData, side: str, bodies: tuple[int, ...], hand: list[int]
) -> Limb:
    """An arm: its tip is the point of the hand's geometry (visual or not) or centre of mass
    farthest from the shoulder; without wrist joints the wrist lies on the elbow -> tip line
    (WRIST_SHARE), and so it does where the only joints past the elbow turn the forearm about
    its own length (an elbow roll: the older G1's, 10 cm past the elbow, whose hand is part of
    that link), unless the hand is a link of its own without joints: the wrist is where it is
    attached. Past an elbow with no joint after it, a link attached on the elbow -> tip line
    (within ALONG), with at least half a human hand past it (scaled by the upper arm), holds
    the wrist instead where that gives the forearm the human's length against the upper arm
    more closely (GMR's T1, whose file leaves the wrist joints out: the WRIST_SHARE point lies
    33 cm past a 21 cm upper arm, the hand is attached 22 cm past it, its tip 19 cm further)."""
    joints = _chain_joints(model, bodies)
    start = data.xanchor[joints[0]]
    best, best_d = data.xpos[bodies[-1]].copy(), -1.0
    # The hand's geoms, and its links' centres of mass (an arm written without geometry).
    points = [_geom_world_points(model, data, g) for g in range(model.ngeom) if model.geom_bodyid[g] in hand]
    points.append((data.xipos[hand], np.zeros(len(hand))))
    for pts, rad in points:
        if not len(pts):
            continue
        d = np.linalg.norm(pts - start, axis=1) + rad
        i = int(np.argmax(d))
        if d[i] > best_d:
            best_d = float(d[i])
            direction = (pts[i] - start) / max(float(np.linalg.norm(pts[i] - start)), 1e-9)
            best = pts[i] + rad[i] * direction
    limb = limb_anatomy(model, data, side, bodies, best)
    if limb.middle_joint is None:
        return limb
    along = (best - limb.middle) / max(float(np.linalg.norm(best - limb.middle)), 1e-9)
    if any(abs(float(data.xaxis[j] @ along)) < ACROSS for j in limb.end_joints):
        return limb  # a wrist that bends the hand
    if limb.end_joints and model.body_jntnum[limb.end_body] == 0:
        return replace(limb, end=data.xpos[limb.end_body].copy())  # a rigid hand on a forearm roll
    # No wrist joint: the wrist sits WRIST_SHARE of the way from the elbow to the hand's tip,
    # or where a link past the elbow is attached on that line (a wrist whose joints the file
    # leaves out), whichever gives the forearm the human's length against the upper arm.
    wrist = limb.middle + WRIST_SHARE * (best - limb.middle)
    upper = max(float(np.linalg.norm(limb.middle - limb.root)), 1e-9)
    candidates = [wrist]
    for b in welded_below(model, limb.end_body):
        out = data.xpos[b] - limb.middle
        on_line = float(out @ along) >= (1.0 - ALONG) * float(np.linalg.norm(out)) > 0.0
        # ...with a hand past it: its tip at least half a human hand away, against the upper arm
        # (the MuJoCo humanoid's hand is a ball whose centre is its body's origin).
        hand_past = float(np.linalg.norm(best - data.xpos[b])) / upper >= HUMAN_HALF_HAND / HUMAN_UPPER_ARM
        if on_line and hand_past:
            candidates.append(data.xpos[b].copy())

    def off_human(point: np.ndarray) -> float:
        return abs(float(np.linalg.norm(point - limb.middle)) / upper - HUMAN_FOREARM / HUMAN_UPPER_ARM)

    return replace(limb, end=min(candidates, key=off_human))
