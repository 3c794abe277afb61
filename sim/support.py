"""Support of the robot in a kinematic replay: heights above the floor, feet, flights, contacts.

Heights above the floor come from the geoms' support functions
(:func:`sim.geometry.support_heights`); a frame is supported when some robot geom is near the
floor or an obstacle, an unsupported run is a flight when its centre of mass follows a
ballistic arc, else the robot floats. Stance feet are measured for sliding, and the contacts
that can carry load go on to the dynamics check. Used by :mod:`sim.kinematic`.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.geoms import geom_local_points
from sim.config import CheckConfig
from sim.failures import Failure, from_mask, runs
from sim.geometry import support_heights
from sim.replay import Contacts, Replay
from sim.world import CheckWorld


@dataclass
class SupportContacts:
    """Contacts able to carry load (robot geom within ``support_height_m`` of floor/obstacle)."""

    frame: np.ndarray
    pos: np.ndarray
    normal: np.ndarray
    body: np.ndarray
    friction: np.ndarray


def _contact_friction(m: mujoco.MjModel, g1: np.ndarray, g2: np.ndarray) -> np.ndarray:
    """MuJoCo's sliding friction of a geom pair: the higher-priority geom's, else the max."""
    f1, f2 = m.geom_friction[g1, 0], m.geom_friction[g2, 0]
    p1, p2 = m.geom_priority[g1], m.geom_priority[g2]
    return np.where(p1 > p2, f1, np.where(p2 > p1, f2, np.maximum(f1, f2)))


def _ballistic(com_z: np.ndarray, fps: float, g: float, tol: float) -> bool:
    """Does a height sequence fit z0 + v0 t - g t^2 / 2 within ``tol`` (RMS)?"""
    t = np.arange(com_z.size) / fps
    target = com_z + 0.5 * g * t**2
    if com_z.size < 3:
        return True
    coef = np.polyfit(t, target, 1)
    return float(np.sqrt(np.mean((np.polyval(coef, t) - target) ** 2))) <= tol


HEIGHT_CUTOFF_M = 0.10
"""Mesh geoms are evaluated vertex by vertex only when they may come lower than this."""


def floor_heights(world: CheckWorld, rep: Replay) -> np.ndarray:
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


def _world_points(rep: Replay, col: int, local: np.ndarray) -> np.ndarray:
    """(T, n, 3) world positions of a geom's ``local`` points (n, 3) in every replayed frame."""
    rot = rep.geom_xmat[:, col].reshape(-1, 3, 3)
    return rep.geom_xpos[:, col, None, :] + np.einsum("tij,nj->tni", rot, local)


def foot_measures(
    world: CheckWorld,
    rep: Replay,
    geom_row: np.ndarray,
    support_dist: np.ndarray,
    heights: np.ndarray,
    fps: float,
    config: CheckConfig,
) -> tuple[dict[str, np.ndarray], list[Failure]]:
    """Foot heights, stance between consecutive frames and the stance foot's horizontal slide.

    ``geom_row``: (ngeom,) the column of each robot geom in ``support_dist`` and ``heights`` (T, G).
    """
    T, F = support_dist.shape[0], len(world.feet)
    height = np.full((T, F), np.nan)
    stance = np.zeros((T, F), dtype=bool)
    slide = np.zeros((T, F))
    failures: list[Failure] = []
    for f, foot in enumerate(world.feet):
        cols = geom_row[foot.geoms]
        if heights.size and not np.isnan(heights[:, cols]).all():
            height[:, f] = np.nanmin(heights[:, cols], axis=1)
        down = support_dist[:, cols] < config.stance_height_m  # (T, g)
        stance[1:, f] = (down[1:] & down[:-1]).any(axis=1)
        step = np.full(T - 1, np.inf)
        for k, (g, col) in enumerate(zip(foot.geoms, cols, strict=True)):
            # corners, rims, end centres; a mesh's hull vertices as the world keeps them
            local = world.hull_vertices.get(int(g))
            if local is None:
                local = geom_local_points(world.model, int(g))[0]
            points = _world_points(rep, col, local if len(local) else np.zeros((1, 3)))
            # a point is on the floor when its geom is and it is as low as the geom's lowest point
            low = points[:, :, 2] - points[:, :, 2].min(axis=1, keepdims=True) < config.stance_height_m
            on = down[:, [k]] & low  # (T, n)
            moved = np.linalg.norm(points[1:, :, :2] - points[:-1, :, :2], axis=2)
            stayed = np.where(on[1:] & on[:-1], moved, np.inf).min(axis=1)
            either = np.where(on[1:] | on[:-1], moved, np.inf).min(axis=1)  # it rocked over in one step
            both = down[1:, k] & down[:-1, k]  # only a geom down in both frames counts
            step = np.fmin(step, np.where(both, np.where(np.isfinite(stayed), stayed, either), np.inf))
        # the point that stayed on the floor moved least: a foot rolling over its toe or heel
        # edge keeps that edge still, however far its body and its geoms' centres travel
        slide[1:, f] = np.where(stance[1:, f], step, 0.0)
        fast = stance[:, f] & (slide[:, f] * fps > config.max_foot_slide_speed)
        failures += from_mask("foot_sliding", fast, slide[:, f], robot_body=foot.name, total=True)
    return {"foot_height": height, "foot_stance": stance, "foot_slide": slide}, failures


def support_measures(
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
    for a, b in runs(np.asarray(~supported, dtype=bool)):
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


def support_contacts(world: CheckWorld, sc: Contacts, config: CheckConfig) -> SupportContacts:
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
