"""Collision-only copies of the model used by the kinematic replay.

The user's model is never modified. Two copies are made (MuJoCo's collision filters: contype/conaffinity,
``<exclude>``, ``<pair>`` and the parent-child filter, MuJoCo documentation, Collision detection):

* the **scene model** collides the robot with the floor and the obstacles through a
  dedicated contype/conaffinity bit (robot geoms: contype; floor and obstacles: conaffinity),
  whatever masks the scene uses; exclusions that involve a non-robot body are neutralised;
  floor and obstacle geoms get a ``gap`` so that near misses are reported (``dist > 0``)
  without ever generating force (gap, not margin). In the default self-collision mode the
  robot keeps its own bits too, so one pass also finds robot-robot contacts with the MJCF's
  masks, ``<exclude>`` pairs, explicit ``<pair>`` elements and MuJoCo's parent-child filter;
* the **self model** (``capsules`` mode only) collides robot geoms with each other, every
  robot mesh collider replaced by a capsule fitted to its hull (MuJoCo collides meshes as
  convex hulls, which overlap near concave regions), with the same filters.

After editing geom fields of a compiled model the body-level copies must be updated too: the
broad phase reads ``body_contype``/``body_conaffinity`` and the mid phase ``body_margin``.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from sim.geometry import fit_capsule
from sim.world import CheckWorld

CAPSULE_BVH_SLACK_M = 0.05
"""Padding of the robot bodies' bounding-volume trees when capsules replace meshes."""

SCENE_BIT = 1 << 30
"""Collision bit reserved for robot-vs-scene detection in the scene model."""


def _refresh_body_fields(m: mujoco.MjModel, slack: float = 0.0) -> None:
    """Recompute the body-level copies of geom fields that the broad and mid phase read.

    ``body_margin`` (the largest margin + gap of a body's geoms) inflates the bounding-volume
    tree of multi-geom bodies; left at its compiled value, a gap added after compilation is
    ignored for e.g. the G1 foot with its four sole spheres.
    """
    m.body_contype[:] = 0
    m.body_conaffinity[:] = 0
    np.bitwise_or.at(m.body_contype, m.geom_bodyid, m.geom_contype)
    np.bitwise_or.at(m.body_conaffinity, m.geom_bodyid, m.geom_conaffinity)
    m.body_margin[:] = 0.0
    np.maximum.at(m.body_margin, m.geom_bodyid, m.geom_margin + m.geom_gap + slack)


def _enable_contacts(m: mujoco.MjModel) -> None:
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)


def scene_model(
    world: CheckWorld, floor_gap: float, obstacle_gap: float, with_self: bool = False
) -> mujoco.MjModel:
    """Copy of the model where robot-vs-(floor, obstacle) pairs collide through a dedicated bit.

    With ``with_self`` the robot keeps its own contype/conaffinity bits as well, so the same
    pass also finds the MJCF's robot-robot contacts (exclusions between robot bodies kept).
    """
    m = copy.deepcopy(world.model)
    _enable_contacts(m)
    robot = world.robot_geoms
    scene = np.concatenate([world.floor_geoms, world.obstacle_geoms]).astype(np.int64)
    own_type = m.geom_contype[robot].copy() & ~SCENE_BIT
    own_affinity = m.geom_conaffinity[robot].copy() & ~SCENE_BIT
    m.geom_contype[:] = 0
    m.geom_conaffinity[:] = 0
    m.geom_contype[robot] = SCENE_BIT | (own_type if with_self else 0)
    m.geom_conaffinity[robot] = own_affinity if with_self else 0
    m.geom_conaffinity[scene] = SCENE_BIT
    m.geom_margin[:] = 0.0
    m.geom_gap[:] = 0.0
    m.geom_gap[world.floor_geoms] = floor_gap
    m.geom_gap[world.obstacle_geoms] = obstacle_gap
    if m.npair:  # explicit <pair>s still collide; contacts are sorted out by geom afterwards
        m.pair_margin[:] = 0.0
        m.pair_gap[:] = 0.0
    _neutralise_exclusions(m, world)
    _refresh_body_fields(m)
    return m


def self_model(world: CheckWorld, capsules: bool) -> mujoco.MjModel:
    """Copy of the model where only robot-vs-robot pairs collide (the MJCF's own filters)."""
    m = copy.deepcopy(world.model)
    _enable_contacts(m)
    robot = np.zeros(m.ngeom, dtype=bool)
    robot[world.robot_geoms] = True
    m.geom_contype[~robot] = 0
    m.geom_conaffinity[~robot] = 0
    m.geom_gap[:] = 0.0
    m.geom_margin[:] = 0.0
    if m.npair:
        m.pair_margin[:] = 0.0
        m.pair_gap[:] = 0.0
    if capsules:
        _meshes_to_capsules(m, world)
    # capsules may poke out of the compiled (mesh-based) bounding-volume tree: pad it
    _refresh_body_fields(m, slack=CAPSULE_BVH_SLACK_M if capsules else 0.0)
    return m


def _neutralise_exclusions(m: mujoco.MjModel, world: CheckWorld) -> None:
    """Point every <exclude> that involves a non-robot body at world-world (never a pair).

    Such exclusions would hide robot-vs-scene contacts (e.g. a scene excluding world <-> feet
    to keep the floor out of its own metrics); exclusions between robot bodies are the MJCF's
    self-collision filter and stay.
    """
    robot = set(world.robot_bodies.tolist())
    for i, sig in enumerate(m.exclude_signature.tolist()):
        if not ((sig >> 16) in robot and (sig & 0xFFFF) in robot):
            m.exclude_signature[i] = 0
    order = np.argsort(m.exclude_signature, kind="stable")  # the collider walks them sorted
    m.exclude_signature[:] = m.exclude_signature[order]


def _meshes_to_capsules(m: mujoco.MjModel, world: CheckWorld) -> None:
    """Replace robot mesh geoms by capsules fitted to their hulls (in place, compiled model)."""
    for g, verts in world.hull_vertices.items():
        centre, axis, radius, half = fit_capsule(verts)
        # rotation taking the geom frame's z onto the capsule axis (expressed in the geom frame)
        local = np.zeros(4)
        mujoco.mju_quatZ2Vec(local, axis)
        # compose: world <- body (geom_quat) <- capsule frame (local)
        quat = np.zeros(4)
        mujoco.mju_mulQuat(quat, m.geom_quat[g], local)
        offset = np.zeros(3)
        mujoco.mju_rotVecQuat(offset, centre, m.geom_quat[g])
        m.geom_pos[g] = m.geom_pos[g] + offset
        m.geom_quat[g] = quat
        m.geom_type[g] = mujoco.mjtGeom.mjGEOM_CAPSULE
        m.geom_size[g] = (radius, half, 0.0)
        m.geom_dataid[g] = -1
        m.geom_rbound[g] = radius + half
        m.geom_aabb[g] = (0.0, 0.0, 0.0, radius, radius, radius + half)
        m.geom_sameframe[g] = 0  # the geom frame no longer coincides with the body frame
