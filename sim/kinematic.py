"""Kinematic replay check: penetration, floor, self-collision, limits, sliding, floating.

The trajectory is replayed pose by pose with ``mj_kinematics`` + ``mj_collision`` on two
collision-only copies of the model (:mod:`sim.colliders`): robot vs scene (with a ``gap``
so near misses are measured) and robot vs robot. Contacts are gathered for every frame and
turned into per-frame, per-robot-body measurements with numpy afterwards; geom poses are
recorded for the analytic floor heights (:func:`sim.geometry.support_heights`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.colliders import scene_model, self_model
from sim.config import CheckConfig
from sim.failures import Failure, from_events, from_mask, runs
from sim.geometry import support_heights
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
        return cls(*(np.concatenate([getattr(a, k), getattr(b, k)]) for k in
                     ("frame", "robot_geom", "other_geom", "dist", "pos", "normal")))

    def select(self, mask: np.ndarray) -> Contacts:
        return Contacts(self.frame[mask], self.robot_geom[mask], self.other_geom[mask], self.dist[mask],
                        self.pos[mask], self.normal[mask])


@dataclass
class SupportContacts:
    """Contacts able to carry load (robot geom within ``support_height_m`` of floor/obstacle)."""

    frame: np.ndarray
    pos: np.ndarray
    normal: np.ndarray
    body: np.ndarray
    friction: np.ndarray


@dataclass
class KinematicResult:
    """Per-frame measurements of the kinematic replay. T = frames, B = robot bodies
    (``CheckWorld.robot_bodies`` order), J = 1-DoF joints, F = feet.

    Attributes:
        obstacle_penetration: (T,) deepest robot-obstacle overlap (m, >= 0).
        clearance: (T,) smallest robot-obstacle signed distance (m), NaN when no obstacle is
            within ``clearance_sense_m`` (or there are no obstacles).
        floor_penetration: (T,) depth of the lowest robot collision point below the floor (m, >= 0).
        lowest_height: (T,) height of the lowest robot collision point above the floor plane
            (m; NaN without a plane floor).
        self_collision: (T,) deepest robot-robot overlap (m, >= 0).
        body_obstacle_penetration, body_floor_penetration, body_self_collision: (T, B) depths (m).
        body_clearance: (T, B) smallest signed distance of each robot body to any obstacle (m;
            NaN beyond ``clearance_sense_m``): where the feedback loop can ask for more margin.
        joint_position: (T, J); joint_limit_violation: (T, J) overshoot past the range (>= 0);
        joint_limit_margin: (T,) smallest distance to a limit over joints (negative = outside).
        joint_speed: (T, J) the larger |velocity| of the steps into and out of the frame;
        joint_velocity_ratio: (T, J) speed / allowed speed.
        foot_height: (T, F) lowest point of each foot above the floor plane (NaN without one).
        foot_stance: (T, F) the foot touches a support in frames t-1 and t.
        foot_slide: (T, F) horizontal slide of the stance foot from t-1 to t (m).
        supported: (T,) some robot geom is within ``support_height_m`` of floor/obstacle.
        support_gap: (T,) distance of the robot's lowest point from the nearest support (m).
        flight: (T,) unsupported frame accepted as part of a ballistic flight.
        floating: (T,) unsupported frame that is not a flight.
        com: (T, 3) whole-robot centre of mass (world).
        support: contacts that can carry load, for the dynamics check.
        contacts: every robot-scene and robot-robot contact found.
        failures: merged failures of the kinematic checks.
    """

    fps: float
    obstacle_penetration: np.ndarray
    clearance: np.ndarray
    floor_penetration: np.ndarray
    lowest_height: np.ndarray
    self_collision: np.ndarray
    body_obstacle_penetration: np.ndarray
    body_clearance: np.ndarray
    body_floor_penetration: np.ndarray
    body_self_collision: np.ndarray
    joint_position: np.ndarray
    joint_limit_violation: np.ndarray
    joint_limit_margin: np.ndarray
    joint_speed: np.ndarray
    joint_velocity_ratio: np.ndarray
    foot_height: np.ndarray
    foot_stance: np.ndarray
    foot_slide: np.ndarray
    supported: np.ndarray
    support_gap: np.ndarray
    flight: np.ndarray
    floating: np.ndarray
    com: np.ndarray
    support: SupportContacts
    contacts: Contacts
    failures: list[Failure] = field(default_factory=list)

    @property
    def num_frames(self) -> int:
        return int(self.obstacle_penetration.shape[0])


# ----------------------------------------------------------------------------------- replay

@dataclass
class _Replay:
    scene: Contacts
    self_: Contacts
    geom_xpos: np.ndarray      # (T, G, 3) robot collision geoms
    geom_xmat: np.ndarray      # (T, G, 9)
    plane_xpos: np.ndarray     # (T, P, 3) floor planes
    plane_xmat: np.ndarray     # (T, P, 9)
    body_xipos: np.ndarray     # (T, B, 3) robot body centres of mass


def _gather(buf: list) -> Contacts:
    if not buf:
        return Contacts.empty()
    frames = np.concatenate([np.full(len(d), f, dtype=np.int64) for f, _, d, _, _ in buf])
    geom = np.concatenate([g for _, g, _, _, _ in buf]).astype(np.int64)
    dist = np.concatenate([d for _, _, d, _, _ in buf])
    pos = np.concatenate([p for _, _, _, p, _ in buf])
    normal = np.concatenate([n for _, _, _, _, n in buf])
    return Contacts(frames, geom[:, 0], geom[:, 1], dist, pos, normal)


def _replay(world: CheckWorld, qpos: np.ndarray, half: np.ndarray, fps: float, config: CheckConfig) -> _Replay:
    T = qpos.shape[0]
    floor_gap = max(config.stance_height_m, config.support_height_m)
    obstacle_gap = max(config.clearance_sense_m, config.support_height_m, config.stance_height_m)
    merged = config.self_collision == "model"
    ms = world.derived(("scene", floor_gap, obstacle_gap, merged),
                       lambda: scene_model(world, floor_gap, obstacle_gap, with_self=merged))
    passes = [(ms, mujoco.MjData(ms), [])]
    if config.self_collision == "capsules":
        mself = world.derived(("self", True), lambda: self_model(world, capsules=True))
        passes.append((mself, mujoco.MjData(mself), []))

    substeps = int(config.substeps)
    dense, owner = interpolate(world.model, qpos, half, fps, substeps)
    record = np.zeros(dense.shape[0], dtype=bool)
    record[::substeps + 1] = True
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
                buf.append((frame, c.geom[:n].copy(), c.dist[:n].copy(), c.pos[:n].copy(), c.frame[:n, :3].copy()))
        if record[k]:
            block_xpos[t] = xpos[lo:hi]
            block_xmat[t] = xmat[lo:hi]
            body_xipos[t] = xipos
            t += 1
    plane_xpos = np.empty((T, planes.size, 3))
    plane_xmat = np.empty((T, planes.size, 9))
    if planes.size:  # floor planes are static unless they sit on a mocap body
        moving = bool((world.model.body_mocapid[world.model.geom_bodyid[planes]] >= 0).any()) and mocap is not None
        data = mujoco.MjData(world.model)
        for t_ in range(T if moving else 1):
            if moving:
                data.mocap_pos[:] = mocap[0][t_ * (substeps + 1)]
                data.mocap_quat[:] = mocap[1][t_ * (substeps + 1)]
            mujoco.mj_kinematics(world.model, data)
            plane_xpos[t_:] = data.geom_xpos[planes]
            plane_xmat[t_:] = data.geom_xmat[planes]
    scene = _gather(passes[0][2])
    self_ = scene if merged else (_gather(passes[1][2]) if len(passes) > 1 else Contacts.empty())
    return _Replay(scene, self_, block_xpos[:, rg - lo], block_xmat[:, rg - lo], plane_xpos, plane_xmat,
                   body_xipos[:, rb])


# ------------------------------------------------------------------------------- measures

def _orient(world: CheckWorld, c: Contacts) -> Contacts:
    """Put the robot geom first and make the normal point into the robot."""
    is_robot = np.zeros(world.model.ngeom, dtype=bool)
    is_robot[world.robot_geoms] = True
    swap = ~is_robot[c.robot_geom]
    g1 = np.where(swap, c.other_geom, c.robot_geom)
    g2 = np.where(swap, c.robot_geom, c.other_geom)
    # MuJoCo's normal points from geom1 to geom2: into the robot when the robot is geom2.
    normal = np.where(swap[:, None], c.normal, -c.normal)
    return Contacts(c.frame, g1, g2, c.dist, c.pos, normal)


def _contact_friction(m: mujoco.MjModel, g1: np.ndarray, g2: np.ndarray) -> np.ndarray:
    """MuJoCo's sliding friction of a geom pair: the higher-priority geom's, else the max."""
    f1, f2 = m.geom_friction[g1, 0], m.geom_friction[g2, 0]
    p1, p2 = m.geom_priority[g1], m.geom_priority[g2]
    return np.where(p1 > p2, f1, np.where(p2 > p1, f2, np.maximum(f1, f2)))


def _body_max(T: int, nb: int, frames: np.ndarray, body_index: np.ndarray, depth: np.ndarray) -> np.ndarray:
    out = np.zeros((T, nb))
    if frames.size:
        np.maximum.at(out, (frames, body_index), depth)
    return out


def _ballistic(com_z: np.ndarray, fps: float, g: float, tol: float) -> bool:
    """Does a height sequence fit z0 + v0 t - g t^2 / 2 within ``tol`` (RMS)?"""
    t = np.arange(com_z.size) / fps
    target = com_z + 0.5 * g * t ** 2
    if com_z.size < 3:
        return True
    coef = np.polyfit(t, target, 1)
    return float(np.sqrt(np.mean((np.polyval(coef, t) - target) ** 2))) <= tol


def kinematic_check(world: CheckWorld, qpos: np.ndarray, fps: float, half: np.ndarray,
                    config: CheckConfig) -> KinematicResult:
    """Replay ``qpos`` (T, nq) kinematically and measure every kinematic failure kind.

    Args:
        world: the robot + scene (:func:`sim.world.make_world`).
        qpos: validated (T, nq) trajectory (:func:`sim.trajectory.validate_qpos`).
        fps: frames per second.
        half: (T-1, nv) velocities between consecutive frames (:mod:`sim.trajectory`).
        config: thresholds.
    """
    m = world.model
    T = qpos.shape[0]
    rep = _replay(world, qpos, half, fps, config)
    body_index = np.full(m.nbody, -1, dtype=np.int64)
    body_index[world.robot_bodies] = np.arange(world.robot_bodies.size)
    geom_index = np.full(m.ngeom, -1, dtype=np.int64)
    geom_index[world.robot_geoms] = np.arange(world.robot_geoms.size)
    category = np.zeros(m.ngeom, dtype=np.int8)  # 1 robot, 2 floor, 3 obstacle
    category[world.robot_geoms] = 1
    category[world.floor_geoms] = 2
    category[world.obstacle_geoms] = 3
    nb = world.robot_bodies.size
    failures: list[Failure] = []

    # --- robot vs scene contacts
    sc = _orient(world, rep.scene)
    sc = sc.select((category[sc.robot_geom] == 1) & (category[sc.other_geom] >= 2))
    sc_body = body_index[m.geom_bodyid[sc.robot_geom]]
    obst = category[sc.other_geom] == 3
    floor = category[sc.other_geom] == 2

    clearance = np.full(T, np.inf)
    if obst.any():
        np.minimum.at(clearance, sc.frame[obst], sc.dist[obst])
    clearance[~np.isfinite(clearance)] = np.nan
    body_clear = np.full((T, nb), np.inf)
    if obst.any():
        np.minimum.at(body_clear, (sc.frame[obst], sc_body[obst]), sc.dist[obst])
    body_clear[~np.isfinite(body_clear)] = np.nan
    pen = np.maximum(-sc.dist, 0.0)
    body_obst = _body_max(T, nb, sc.frame[obst], sc_body[obst], pen[obst])
    body_floor = _body_max(T, nb, sc.frame[floor], sc_body[floor], pen[floor])

    def scene_label(key: tuple[int, int]) -> tuple[str, str]:
        return world.body_name(world.robot_bodies[key[0]]), world.geom_label(key[1])

    for kind, mask, tol in (("obstacle_penetration", obst, config.obstacle_penetration_m),
                            ("floor_penetration", floor, config.floor_penetration_m)):
        hit = mask & (pen > tol)
        failures += from_events(kind, sc.frame[hit], list(zip(sc_body[hit].tolist(), sc.other_geom[hit].tolist())),
                                pen[hit], scene_label)

    # --- self collision
    body_self = np.zeros((T, nb))
    sf = Contacts.empty()
    if config.self_collision != "off":
        sf = rep.self_
        sf = sf.select((category[sf.robot_geom] == 1) & (category[sf.other_geom] == 1) & (sf.dist < 0))
        b1 = body_index[m.geom_bodyid[sf.robot_geom]]
        b2 = body_index[m.geom_bodyid[sf.other_geom]]
        depth = -sf.dist
        body_self = np.maximum(_body_max(T, nb, sf.frame, b1, depth), _body_max(T, nb, sf.frame, b2, depth))
        hit = depth > config.self_collision_m
        lo, hi = np.minimum(b1, b2)[hit], np.maximum(b1, b2)[hit]
        failures += from_events(
            "self_collision", sf.frame[hit], list(zip(lo.tolist(), hi.tolist())), depth[hit],
            lambda key: (world.body_name(world.robot_bodies[key[0]]), world.body_name(world.robot_bodies[key[1]])))

    # --- support distances and analytic floor heights
    support_dist = np.full((T, world.robot_geoms.size), np.inf)
    np.minimum.at(support_dist, (sc.frame, geom_index[sc.robot_geom]), sc.dist)
    heights = _floor_heights(world, rep)
    lowest = np.nanmin(heights, axis=1) if heights.size and not np.isnan(heights).all() else np.full(T, np.nan)

    # --- feet: stance and sliding
    F = len(world.feet)
    foot_height = np.full((T, F), np.nan)
    foot_stance = np.zeros((T, F), dtype=bool)
    foot_slide = np.zeros((T, F))
    for f, foot in enumerate(world.feet):
        cols = geom_index[foot.geoms]
        if heights.size:
            foot_height[:, f] = np.nanmin(heights[:, cols], axis=1) if not np.isnan(heights[:, cols]).all() else np.nan
        touching = support_dist[:, cols] < config.stance_height_m  # (T, g)
        both = touching[1:] & touching[:-1]
        step = np.linalg.norm(rep.geom_xpos[1:, cols, :2] - rep.geom_xpos[:-1, cols, :2], axis=2)
        step = np.where(both, step, np.inf).min(axis=1)
        stance = np.isfinite(step)
        foot_stance[1:, f] = stance
        foot_slide[1:, f] = np.where(stance, step, 0.0)
        fast = foot_stance[:, f] & (foot_slide[:, f] * fps > config.max_foot_slide_speed)
        failures += from_mask("foot_sliding", fast, foot_slide[:, f], robot_body=foot.name, total=True)

    # --- support, flight and floating
    supported = (support_dist < config.support_height_m).any(axis=1)
    masses = m.body_mass[world.robot_bodies]
    com = np.einsum("tbk,b->tk", rep.body_xipos, masses) / masses.sum()
    gap = np.nanmin(np.column_stack([support_dist.min(axis=1), np.where(np.isnan(lowest), np.inf, lowest)]), axis=1)
    gap = np.where(np.isfinite(gap), gap, np.nan)
    flight = np.zeros(T, dtype=bool)
    floating = np.zeros(T, dtype=bool)
    g = float(np.linalg.norm(m.opt.gravity))
    for a, b in runs(~supported):
        span = slice(a, b + 1)
        short = (b - a + 1) / fps <= config.max_flight_s
        if short and _ballistic(com[span, 2], fps, g, config.ballistic_tol_m):
            flight[span] = True
        else:
            floating[span] = True
    low_body = _lowest_body(world, heights)
    for a, b in runs(floating):
        body = low_body[a + int(np.nanargmax(np.nan_to_num(gap[a:b + 1], nan=-np.inf)))] if low_body else None
        vals = np.nan_to_num(gap[a:b + 1], nan=max(config.support_height_m, config.clearance_sense_m))
        failures.append(Failure("floating", a, b, body, None, float(np.max(vals))))

    # --- joint limits and velocities
    J = world.joints
    jpos = qpos[:, J.qpos_adr]
    over = np.where(J.limited, np.maximum(jpos - J.upper, J.lower - jpos), -np.inf)
    violation = np.maximum(over, 0.0)
    margin = np.min(np.where(J.limited, -over, np.inf), axis=1) if J.names else np.full(T, np.nan)
    margin = np.where(np.isfinite(margin), margin, np.nan)
    speed = _joint_speed(half, J.dof_adr, T)
    limits = np.array([config.velocity_limit(n) for n in J.names]) * config.velocity_limit_factor
    ratio = speed / limits if J.names else np.zeros((T, 0))
    for j, name in enumerate(J.names):
        failures += from_mask("joint_limit", violation[:, j] > config.joint_limit_tol_rad, violation[:, j],
                              robot_body=J.bodies[j], joint=name)
        failures += from_mask("joint_velocity", ratio[:, j] > 1.0, speed[:, j] - limits[j],
                              robot_body=J.bodies[j], joint=name)

    support = _support_contacts(world, sc, config)
    return KinematicResult(
        fps=fps,
        obstacle_penetration=body_obst.max(axis=1) if nb else np.zeros(T),
        clearance=clearance,
        floor_penetration=body_floor.max(axis=1) if nb else np.zeros(T),
        lowest_height=lowest,
        self_collision=body_self.max(axis=1) if nb else np.zeros(T),
        body_obstacle_penetration=body_obst,
        body_clearance=body_clear,
        body_floor_penetration=body_floor,
        body_self_collision=body_self,
        joint_position=jpos,
        joint_limit_violation=violation,
        joint_limit_margin=margin,
        joint_speed=speed,
        joint_velocity_ratio=ratio,
        foot_height=foot_height,
        foot_stance=foot_stance,
        foot_slide=foot_slide,
        supported=supported,
        support_gap=gap,
        flight=flight,
        floating=floating,
        com=com,
        support=support,
        contacts=Contacts.concat(sc, sf),
        failures=failures,
    )


HEIGHT_CUTOFF_M = 0.10
"""Mesh geoms are evaluated vertex by vertex only when they may come lower than this."""


def _joint_speed(half: np.ndarray, dofs: np.ndarray, T: int) -> np.ndarray:
    """(T, J) joint speed at each frame: the larger of the two adjacent half-step speeds.

    Central averaging would halve a one-frame jump; the half steps are what the robot must
    actually move between frames.
    """
    speed = np.zeros((T, dofs.size))
    if T >= 2:
        step = np.abs(half[:, dofs])
        speed[:-1] = step
        speed[1:] = np.maximum(speed[1:], step)
    return speed


def _floor_heights(world: CheckWorld, rep: _Replay) -> np.ndarray:
    """(T, G) height of each robot geom's lowest point above the floor (min over planes);
    exact up to :data:`HEIGHT_CUTOFF_M`, a lower bound above it."""
    T, P = rep.plane_xpos.shape[:2]
    if P == 0:
        return np.zeros((T, 0))
    heights = None
    for p in range(P):
        normal = rep.plane_xmat[:, p].reshape(T, 3, 3)[:, :, 2]
        h = support_heights(world.model, world.robot_geoms, rep.geom_xpos, rep.geom_xmat, rep.plane_xpos[:, p],
                            normal, world.hull_vertices, cutoff=HEIGHT_CUTOFF_M)
        heights = h if heights is None else np.fmin(heights, h)
    return heights


def _lowest_body(world: CheckWorld, heights: np.ndarray) -> list[str]:
    if heights.size == 0:
        return []
    names = [world.body_name(b) for b in world.model.geom_bodyid[world.robot_geoms]]
    filled = np.where(np.isnan(heights), np.inf, heights)
    return [names[i] for i in np.argmin(filled, axis=1)]


def _support_contacts(world: CheckWorld, sc: Contacts, config: CheckConfig) -> SupportContacts:
    near = sc.dist < config.support_height_m
    c = sc.select(near)
    if config.friction is not None:
        mu = np.full(c.frame.size, float(config.friction))
    else:
        mu = _contact_friction(world.model, c.robot_geom, c.other_geom)
    return SupportContacts(c.frame, c.pos, c.normal, world.model.geom_bodyid[c.robot_geom].astype(np.int64), mu)
