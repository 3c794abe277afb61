"""Kinematic replay check: penetration, floor, self-collision, limits, sliding, floating.

:func:`sim.replay.replay` poses every frame and collects MuJoCo contacts; this module turns
them, with numpy, into per-frame and per-robot-body measurements and merged failures. Heights
above the floor, feet, flights and load-carrying contacts are measured in :mod:`sim.support`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from retarget.couplings import joint_couplings
from sim.config import CheckConfig
from sim.failures import Failure, from_events, from_mask
from sim.replay import Contacts, Replay, orient, replay
from sim.support import SupportContacts, floor_heights, foot_measures, support_contacts, support_measures
from sim.world import CheckWorld


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


def _body_max(T: int, nb: int, frames: np.ndarray, body_index: np.ndarray, depth: np.ndarray) -> np.ndarray:
    out = np.zeros((T, nb))
    if frames.size:
        np.maximum.at(out, (frames, body_index), depth)
    return out


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
    heights = floor_heights(world, rep)
    lowest = (
        np.nanmin(heights, axis=1) if heights.size and not np.isnan(heights).all() else np.full(T, np.nan)
    )
    feet, feet_failures = foot_measures(world, rep, ix.geom, support_dist, heights, fps, config)
    support, support_failures = support_measures(world, rep, support_dist, heights, lowest, fps, config)
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
        support=support_contacts(world, sc, config),
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


def _joint_measures(
    world: CheckWorld, qpos: np.ndarray, half: np.ndarray, config: CheckConfig
) -> tuple[dict[str, np.ndarray], list[Failure]]:
    """Joint-limit overshoot and margin, joint speed against velocity limits, joint couplings."""
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
    couplings = world.derived(("couplings",), lambda: joint_couplings(world.model, J.ids))
    if couplings is not None:  # the MJCF's joint equalities (a driven joint's residual)
        off = np.abs(couplings.residual(position))
        for e, j in enumerate(couplings.first):
            failures += from_mask(
                "joint_coupling",
                off[:, e] > config.joint_coupling_tol_rad,
                off[:, e],
                robot_body=J.bodies[j],
                joint=J.names[j],
            )
    return {
        "joint_position": position,
        "joint_limit_violation": violation,
        "joint_limit_margin": np.where(np.isfinite(margin), margin, np.nan),
        "joint_speed": speed,
        "joint_velocity_ratio": ratio,
    }, failures


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
