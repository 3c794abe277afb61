"""Kinematic replay check: penetration, floor, self-collision, limits, sliding, floating.

:func:`sim.replay.replay` poses every frame and collects MuJoCo contacts; this module turns
them, with numpy, into per-frame and per-robot-body measurements and merged failures. Heights
above the floor come from the geoms' support functions (:func:`sim.geometry.support_heights`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.config import CheckConfig
from sim.failures import Failure, from_events, from_mask, runs
from sim.geometry import support_heights
from sim.replay import Contacts, Replay, orient, replay
from sim.world import CheckWorld


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


# ------------------------------------------------------------------------------- measures


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
    target = com_z + 0.5 * g * t**2
    if com_z.size < 3:
        return True
    coef = np.polyfit(t, target, 1)
    return float(np.sqrt(np.mean((np.polyval(coef, t) - target) ** 2))) <= tol


@dataclass(frozen=True)
class _Index:
    """Lookups from model ids to the check's rows: robot body -> B index, robot geom -> G
    index, geom -> category (0 other, 1 robot, 2 floor, 3 obstacle)."""

    body: np.ndarray
    geom: np.ndarray
    category: np.ndarray

    @classmethod
    def of(cls, world: CheckWorld) -> _Index:
        m = world.model
        body = np.full(m.nbody, -1, dtype=np.int64)
        body[world.robot_bodies] = np.arange(world.robot_bodies.size)
        geom = np.full(m.ngeom, -1, dtype=np.int64)
        geom[world.robot_geoms] = np.arange(world.robot_geoms.size)
        category = np.zeros(m.ngeom, dtype=np.int8)
        category[world.robot_geoms] = 1
        category[world.floor_geoms] = 2
        category[world.obstacle_geoms] = 3
        return cls(body, geom, category)


def kinematic_check(
    world: CheckWorld, qpos: np.ndarray, fps: float, half: np.ndarray, config: CheckConfig
) -> KinematicResult:
    """Replay ``qpos`` (T, nq) kinematically and measure every kinematic failure kind.

    Args:
        world: the robot + scene (:func:`sim.world.make_world`).
        qpos: validated (T, nq) trajectory (:func:`sim.trajectory.validate_qpos`).
        fps: frames per second.
        half: (T-1, nv) velocities between consecutive frames (:mod:`sim.trajectory`).
        config: thresholds.
    """
    T = qpos.shape[0]
    rep = replay(world, qpos, half, fps, config)
    ix = _Index.of(world)
    sc, scene, failures = _scene_measures(world, rep, ix, T, config)
    sf, body_self, self_failures = _self_measures(world, rep, ix, T, config)
    support_dist = np.full((T, world.robot_geoms.size), np.inf)  # (T, G) distance to floor/obstacles
    np.minimum.at(support_dist, (sc.frame, ix.geom[sc.robot_geom]), sc.dist)
    heights = _floor_heights(world, rep)
    lowest = (
        np.nanmin(heights, axis=1) if heights.size and not np.isnan(heights).all() else np.full(T, np.nan)
    )
    feet, feet_failures = _foot_measures(world, rep, ix, support_dist, heights, fps, config)
    support, support_failures = _support_measures(world, rep, support_dist, heights, lowest, fps, config)
    joints, joint_failures = _joint_measures(world, qpos, half, config)
    nb = world.robot_bodies.size
    return KinematicResult(
        fps=fps,
        obstacle_penetration=scene["body_obstacle_penetration"].max(axis=1) if nb else np.zeros(T),
        floor_penetration=scene["body_floor_penetration"].max(axis=1) if nb else np.zeros(T),
        lowest_height=lowest,
        self_collision=body_self.max(axis=1) if nb else np.zeros(T),
        body_self_collision=body_self,
        **scene,
        **feet,
        **support,
        **joints,
        support=_support_contacts(world, sc, config),
        contacts=Contacts.concat(sc, sf),
        failures=failures + self_failures + feet_failures + support_failures + joint_failures,
    )


def _scene_measures(
    world: CheckWorld, rep: Replay, ix: _Index, T: int, config: CheckConfig
) -> tuple[Contacts, dict[str, np.ndarray], list[Failure]]:
    """Robot-vs-scene contacts: clearance, obstacle and floor penetration per frame and body."""
    m = world.model
    nb = world.robot_bodies.size
    sc = orient(world, rep.scene)
    sc = sc.select((ix.category[sc.robot_geom] == 1) & (ix.category[sc.other_geom] >= 2))
    body = ix.body[m.geom_bodyid[sc.robot_geom]]
    obst = ix.category[sc.other_geom] == 3
    floor = ix.category[sc.other_geom] == 2
    clearance = np.full(T, np.inf)
    body_clear = np.full((T, nb), np.inf)
    if obst.any():
        np.minimum.at(clearance, sc.frame[obst], sc.dist[obst])
        np.minimum.at(body_clear, (sc.frame[obst], body[obst]), sc.dist[obst])
    pen = np.maximum(-sc.dist, 0.0)
    fields = {
        "clearance": np.where(np.isfinite(clearance), clearance, np.nan),
        "body_clearance": np.where(np.isfinite(body_clear), body_clear, np.nan),
        "body_obstacle_penetration": _body_max(T, nb, sc.frame[obst], body[obst], pen[obst]),
        "body_floor_penetration": _body_max(T, nb, sc.frame[floor], body[floor], pen[floor]),
    }

    def label(key: int) -> tuple[str, str]:
        return world.body_name(world.robot_bodies[key // m.ngeom]), world.geom_label(key % m.ngeom)

    failures: list[Failure] = []
    for kind, mask, tol in (
        ("obstacle_penetration", obst, config.obstacle_penetration_m),
        ("floor_penetration", floor, config.floor_penetration_m),
    ):
        hit = mask & (pen > tol)
        failures += from_events(
            kind, sc.frame[hit], body[hit] * m.ngeom + sc.other_geom[hit], pen[hit], label
        )
    return sc, fields, failures


def _self_measures(
    world: CheckWorld, rep: Replay, ix: _Index, T: int, config: CheckConfig
) -> tuple[Contacts, np.ndarray, list[Failure]]:
    """Robot-robot overlaps per frame and body; failures per body pair."""
    nb = world.robot_bodies.size
    if config.self_collision == "off":
        return Contacts.empty(), np.zeros((T, nb)), []
    m = world.model
    sf = rep.self_
    sf = sf.select((ix.category[sf.robot_geom] == 1) & (ix.category[sf.other_geom] == 1) & (sf.dist < 0))
    b1 = ix.body[m.geom_bodyid[sf.robot_geom]]
    b2 = ix.body[m.geom_bodyid[sf.other_geom]]
    depth = -sf.dist
    body_self = np.maximum(_body_max(T, nb, sf.frame, b1, depth), _body_max(T, nb, sf.frame, b2, depth))
    hit = depth > config.self_collision_m
    lo, hi = np.minimum(b1, b2)[hit], np.maximum(b1, b2)[hit]
    failures = from_events(
        "self_collision",
        sf.frame[hit],
        lo * nb + hi,
        depth[hit],
        lambda key: (
            world.body_name(world.robot_bodies[key // nb]),
            world.body_name(world.robot_bodies[key % nb]),
        ),
    )
    return sf, body_self, failures


def _foot_measures(
    world: CheckWorld,
    rep: Replay,
    ix: _Index,
    support_dist: np.ndarray,
    heights: np.ndarray,
    fps: float,
    config: CheckConfig,
) -> tuple[dict[str, np.ndarray], list[Failure]]:
    """Foot heights, stance between consecutive frames and the stance foot's horizontal slide."""
    T, F = support_dist.shape[0], len(world.feet)
    height = np.full((T, F), np.nan)
    stance = np.zeros((T, F), dtype=bool)
    slide = np.zeros((T, F))
    failures: list[Failure] = []
    for f, foot in enumerate(world.feet):
        cols = ix.geom[foot.geoms]
        if heights.size and not np.isnan(heights[:, cols]).all():
            height[:, f] = np.nanmin(heights[:, cols], axis=1)
        down = support_dist[:, cols] < config.stance_height_m  # (T, g)
        both = down[1:] & down[:-1]
        step = np.linalg.norm(rep.geom_xpos[1:, cols, :2] - rep.geom_xpos[:-1, cols, :2], axis=2)
        step = np.where(both, step, np.inf).min(axis=1)  # the geom that stayed down moved least
        stance[1:, f] = np.isfinite(step)
        slide[1:, f] = np.where(stance[1:, f], step, 0.0)
        fast = stance[:, f] & (slide[:, f] * fps > config.max_foot_slide_speed)
        failures += from_mask("foot_sliding", fast, slide[:, f], robot_body=foot.name, total=True)
    return {"foot_height": height, "foot_stance": stance, "foot_slide": slide}, failures


def _support_measures(
    world: CheckWorld,
    rep: Replay,
    support_dist: np.ndarray,
    heights: np.ndarray,
    lowest: np.ndarray,
    fps: float,
    config: CheckConfig,
) -> tuple[dict[str, np.ndarray], list[Failure]]:
    """Supported frames, ballistic flights and floating (unsupported, not a flight)."""
    m = world.model
    T = support_dist.shape[0]
    supported = (support_dist < config.support_height_m).any(axis=1)
    masses = m.body_mass[world.robot_bodies]
    com = np.einsum("tbk,b->tk", rep.body_xipos, masses) / masses.sum()
    gap = np.fmin(support_dist.min(axis=1), np.where(np.isnan(lowest), np.inf, lowest))
    gap = np.where(np.isfinite(gap), gap, np.nan)
    flight = np.zeros(T, dtype=bool)
    floating = np.zeros(T, dtype=bool)
    g = float(np.linalg.norm(m.opt.gravity))
    edge = int(round(config.flight_edge_s * fps))
    for a, b in runs(~supported):
        span = slice(a, b + 1)
        # The take-off and landing impulses of a kinematic motion are smeared over the frames
        # around the contact (20 fps source, splines): the centre of mass may still rise just
        # after the feet left the floor. The ballistic fit skips flight_edge_s at each end.
        middle = slice(a + edge, b + 1 - edge) if b + 1 - a > 2 * edge + 2 else span
        if (b - a + 1) / fps <= config.max_flight_s and _ballistic(
            com[middle, 2], fps, g, config.ballistic_tol_m
        ):
            flight[span] = True
        else:
            floating[span] = True
    failures = []
    low_body = _lowest_body(world, heights)
    unknown = max(config.support_height_m, config.clearance_sense_m)  # beyond sensing, no plane floor
    for a, b in runs(floating):
        values = np.nan_to_num(gap[a : b + 1], nan=unknown)
        body = low_body[a + int(np.argmax(values))] if low_body else None
        failures.append(Failure("floating", a, b, body, None, float(values.max())))
    return {
        "supported": supported,
        "support_gap": gap,
        "flight": flight,
        "floating": floating,
        "com": com,
    }, failures


def _joint_measures(
    world: CheckWorld, qpos: np.ndarray, half: np.ndarray, config: CheckConfig
) -> tuple[dict[str, np.ndarray], list[Failure]]:
    """Joint-limit overshoot and margin, joint speed against velocity limits."""
    J = world.joints
    T = qpos.shape[0]
    position = qpos[:, J.qpos_adr]
    over = np.where(J.limited, np.maximum(position - J.upper, J.lower - position), -np.inf)
    violation = np.maximum(over, 0.0)
    margin = np.min(np.where(J.limited, -over, np.inf), axis=1) if J.names else np.full(T, np.inf)
    speed = _joint_speed(half, J.dof_adr, T)
    limits = np.array([config.velocity_limit(n) for n in J.names]) * config.velocity_limit_factor
    ratio = speed / limits if J.names else np.zeros((T, 0))
    failures: list[Failure] = []
    for j, name in enumerate(J.names):
        failures += from_mask(
            "joint_limit",
            violation[:, j] > config.joint_limit_tol_rad,
            violation[:, j],
            robot_body=J.bodies[j],
            joint=name,
        )
        failures += from_mask(
            "joint_velocity", ratio[:, j] > 1.0, speed[:, j] - limits[j], robot_body=J.bodies[j], joint=name
        )
    return {
        "joint_position": position,
        "joint_limit_violation": violation,
        "joint_limit_margin": np.where(np.isfinite(margin), margin, np.nan),
        "joint_speed": speed,
        "joint_velocity_ratio": ratio,
    }, failures


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


def _floor_heights(world: CheckWorld, rep: Replay) -> np.ndarray:
    """(T, G) height of each robot geom's lowest point above the floor (min over planes).

    Exact for the feet and primitive geoms up to :data:`HEIGHT_CUTOFF_M`; a mesh geom is
    evaluated vertex by vertex only in frames where it may be the robot's lowest point (its
    bounding sphere reaches below both the cutoff and the lowest primitive/foot point),
    elsewhere its entry is a lower bound that cannot be the minimum. Hull vertices are many
    (hundreds to thousands per G1 link), so this pruning is most of the cost saved.
    """
    T, P = rep.plane_xpos.shape[:2]
    G = world.robot_geoms.size
    if P == 0:
        return np.zeros((T, 0))
    m = world.model
    foot_geoms = np.concatenate([f.geoms for f in world.feet]) if world.feet else np.zeros(0, np.int64)
    feet = np.isin(world.robot_geoms, foot_geoms)
    first = np.flatnonzero(feet | (m.geom_type[world.robot_geoms] != int(mujoco.mjtGeom.mjGEOM_MESH)))
    rest = np.setdiff1d(np.arange(G), first)
    heights = np.full((T, G), np.inf)
    for p in range(P):
        normal = rep.plane_xmat[:, p].reshape(T, 3, 3)[:, :, 2]
        point = rep.plane_xpos[:, p]
        h = np.empty((T, G))
        h[:, first] = _plane_heights(world, rep, first, point, normal, HEIGHT_CUTOFF_M)
        running = np.nanmin(h[:, first], axis=1) if first.size else np.full(T, np.inf)
        if rest.size:
            h[:, rest] = _plane_heights(world, rep, rest, point, normal, np.fmin(HEIGHT_CUTOFF_M, running))
        heights = np.fmin(heights, h)
    return heights


def _plane_heights(
    world: CheckWorld,
    rep: Replay,
    cols: np.ndarray,
    point: np.ndarray,
    normal: np.ndarray,
    cutoff: float | np.ndarray,
) -> np.ndarray:
    return support_heights(
        world.model,
        world.robot_geoms[cols],
        rep.geom_xpos[:, cols],
        rep.geom_xmat[:, cols],
        point,
        normal,
        world.hull_vertices,
        cutoff=cutoff,
    )


def _lowest_body(world: CheckWorld, heights: np.ndarray) -> list[str]:
    if heights.size == 0:
        return []
    names = [world.body_name(b) for b in world.model.geom_bodyid[world.robot_geoms]]
    filled = np.where(np.isnan(heights), np.inf, heights)
    return [names[i] for i in np.argmin(filled, axis=1)]


def _support_contacts(world: CheckWorld, sc: Contacts, config: CheckConfig) -> SupportContacts:
    """Contacts that may carry load: within ``support_height_m`` of the floor or an obstacle.

    A robot geom sunk into the floor still stands on it, but one that has gone into an
    obstacle further than ``obstacle_penetration_m`` is not leaning on it: that contact is a
    penetration failure, its normal is arbitrary, and counting it as support would let the
    obstacle hold the robot up (or twist its wrist) in the dynamics check.
    """
    inside = np.isin(sc.other_geom, world.obstacle_geoms) & (sc.dist < -config.obstacle_penetration_m)
    near = (sc.dist < config.support_height_m) & ~inside
    c = sc.select(near)
    if config.friction is not None:
        mu = np.full(c.frame.size, float(config.friction))
    else:
        mu = _contact_friction(world.model, c.robot_geom, c.other_geom)
    return SupportContacts(
        c.frame, c.pos, c.normal, world.model.geom_bodyid[c.robot_geom].astype(np.int64), mu
    )
