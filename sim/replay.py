"""Replay a trajectory pose by pose and collect MuJoCo contacts (the kinematic check's input).

Every frame (and every interpolated substep) runs ``mj_kinematics`` + ``mj_collision`` on the
collision-only copies of :mod:`sim.colliders`; contacts are copied out as flat arrays with their
frame index, and the poses of the robot's collision geoms and bodies are recorded for the
analytic measures of :mod:`sim.kinematic`.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.colliders import scene_model, self_model
from sim.config import CheckConfig
from sim.trajectory import interpolate
from sim.world import CheckWorld

_PLANE = int(mujoco.mjtGeom.mjGEOM_PLANE)


@dataclass
class Contacts:
    """Flat contact list over all frames; every array has length E (contacts).

    ``robot_geom``/``other_geom`` are ordered robot first; ``normal`` points from the other
    geom into the robot (the direction a support pushes); ``dist`` < 0 is penetration.
    """

    frame: np.ndarray
    robot_geom: np.ndarray
    other_geom: np.ndarray
    dist: np.ndarray
    pos: np.ndarray
    normal: np.ndarray

    @classmethod
    def empty(cls) -> Contacts:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z, z, np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))

    @classmethod
    def concat(cls, a: Contacts, b: Contacts) -> Contacts:
        return cls(
            *(
                np.concatenate([getattr(a, k), getattr(b, k)])
                for k in ("frame", "robot_geom", "other_geom", "dist", "pos", "normal")
            )
        )

    def select(self, mask: np.ndarray) -> Contacts:
        return Contacts(
            self.frame[mask],
            self.robot_geom[mask],
            self.other_geom[mask],
            self.dist[mask],
            self.pos[mask],
            self.normal[mask],
        )


@dataclass
class Replay:
    """What the replay recorded: contacts of both passes, robot geom and body poses per frame."""

    scene: Contacts
    self_: Contacts
    geom_xpos: np.ndarray  # (T, G, 3) robot collision geoms
    geom_xmat: np.ndarray  # (T, G, 9)
    plane_xpos: np.ndarray  # (T, P, 3) floor planes
    plane_xmat: np.ndarray  # (T, P, 9)
    body_xipos: np.ndarray  # (T, B, 3) robot body centres of mass


def _gather(buf: list) -> Contacts:
    if not buf:
        return Contacts.empty()
    frames = np.concatenate([np.full(len(d), f, dtype=np.int64) for f, _, d, _, _ in buf])
    geom = np.concatenate([g for _, g, _, _, _ in buf]).astype(np.int64)
    dist = np.concatenate([d for _, _, d, _, _ in buf])
    pos = np.concatenate([p for _, _, _, p, _ in buf])
    normal = np.concatenate([n for _, _, _, _, n in buf])
    return Contacts(frames, geom[:, 0], geom[:, 1], dist, pos, normal)


def replay(world: CheckWorld, qpos: np.ndarray, half: np.ndarray, fps: float, config: CheckConfig) -> Replay:
    """Pose every frame (and substep) of ``qpos`` and collect contacts and poses.

    Args:
        world: robot + scene; qpos: (T, nq) validated; half: (T-1, nv) half-step velocities
            (for substeps); fps: frame rate; config: sensing distances, collider set, substeps.
    """
    T = qpos.shape[0]
    floor_gap = max(config.stance_height_m, config.support_height_m)
    obstacle_gap = max(config.clearance_sense_m, config.support_height_m, config.stance_height_m)
    merged = config.self_collision == "model"
    ms = world.derived(
        ("scene", floor_gap, obstacle_gap, merged),
        lambda: scene_model(world, floor_gap, obstacle_gap, with_self=merged),
    )
    passes: list[tuple[mujoco.MjModel, mujoco.MjData, list]] = [(ms, mujoco.MjData(ms), [])]
    if config.self_collision == "capsules":
        mself = world.derived(("self", True), lambda: self_model(world, capsules=True))
        passes.append((mself, mujoco.MjData(mself), []))

    substeps = int(config.substeps)
    dense, owner = interpolate(world.model, qpos, half, fps, substeps)
    record = np.zeros(dense.shape[0], dtype=bool)
    record[:: substeps + 1] = True
    mocap = world.mocap_poses(np.arange(dense.shape[0]) / (fps * (substeps + 1)))

    # Robot geoms are recorded as one contiguous block (a slice copy is cheaper than fancy
    # indexing inside the loop) and picked out afterwards.
    rg = world.robot_geoms
    lo, hi = int(rg.min()), int(rg.max()) + 1
    planes = world.floor_geoms[world.model.geom_type[world.floor_geoms] == _PLANE]
    rb = world.robot_bodies
    block_xpos = np.empty((T, hi - lo, 3))
    block_xmat = np.empty((T, hi - lo, 9))
    body_xipos = np.empty((T, world.model.nbody, 3))
    ds = passes[0][1]
    views = [(m, d, buf, d.qpos, d.mocap_pos, d.mocap_quat) for m, d, buf in passes]
    xpos, xmat, xipos = ds.geom_xpos, ds.geom_xmat, ds.xipos
    kinematics, collision = mujoco.mj_kinematics, mujoco.mj_collision
    t = 0
    for k in range(dense.shape[0]):
        frame = int(owner[k])
        for m, d, buf, qv, mpos, mquat in views:
            qv[:] = dense[k]
            if mocap is not None:
                mpos[:] = mocap[0][k]
                mquat[:] = mocap[1][k]
            kinematics(m, d)
            collision(m, d)
            n = d.ncon
            if n:
                c = d.contact
                buf.append(
                    (frame, c.geom[:n].copy(), c.dist[:n].copy(), c.pos[:n].copy(), c.frame[:n, :3].copy())
                )
        if record[k]:
            block_xpos[t] = xpos[lo:hi]
            block_xmat[t] = xmat[lo:hi]
            body_xipos[t] = xipos
            t += 1
    plane_xpos = np.empty((T, planes.size, 3))
    plane_xmat = np.empty((T, planes.size, 9))
    if planes.size:  # floor planes are static unless they sit on a mocap body
        moving = (
            bool((world.model.body_mocapid[world.model.geom_bodyid[planes]] >= 0).any()) and mocap is not None
        )
        data = mujoco.MjData(world.model)
        for t_ in range(T if moving else 1):
            if moving and mocap is not None:
                data.mocap_pos[:] = mocap[0][t_ * (substeps + 1)]
                data.mocap_quat[:] = mocap[1][t_ * (substeps + 1)]
            mujoco.mj_kinematics(world.model, data)
            plane_xpos[t_:] = data.geom_xpos[planes]
            plane_xmat[t_:] = data.geom_xmat[planes]
    scene = _gather(passes[0][2])
    self_ = scene if merged else (_gather(passes[1][2]) if len(passes) > 1 else Contacts.empty())
    return Replay(
        scene,
        self_,
        block_xpos[:, rg - lo],
        block_xmat[:, rg - lo],
        plane_xpos,
        plane_xmat,
        body_xipos[:, rb],
    )


def orient(world: CheckWorld, c: Contacts) -> Contacts:
    """Put the robot geom first and make the normal point into the robot."""
    is_robot = np.zeros(world.model.ngeom, dtype=bool)
    is_robot[world.robot_geoms] = True
    swap = ~is_robot[c.robot_geom]
    g1 = np.where(swap, c.other_geom, c.robot_geom)
    g2 = np.where(swap, c.robot_geom, c.other_geom)
    # MuJoCo's normal points from geom1 to geom2: into the robot when the robot is geom2.
    normal = np.where(swap[:, None], c.normal, -c.normal)
    return Contacts(c.frame, g1, g2, c.dist, c.pos, normal)
