"""Foot-placement planning: a root path and a gait become footholds for both feet.

The root path is the ground point the body travels along, with the body's heading. A gait
clock (cadence in steps per second) proposes swings that alternate between the feet; each
swing lands the foot beside the path where the body will be a little later (``ref_frac``
of the coming stance), turned to the heading there. Swings that would move a foot by less
than a few centimetres (standing still) are skipped, so a person who stops stands on both
feet. Heel-toe roll follows the direction of each step: forward steps strike with the
heel and push off over the toe, backward steps land on the toe and lift over the heel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controlmm.corpus.curves import integrate, wrap_angle
from controlmm.corpus.feet import Stance
from controlmm.corpus.rig import SIDE_SIGN, heading_vectors


@dataclass
class RootPath:
    """Where the body goes: ground positions (T, 2) as (x, z), heading (T,) at times (T,)."""

    t: np.ndarray
    xz: np.ndarray
    yaw: np.ndarray

    def at(self, tq: float) -> tuple[np.ndarray, float]:
        """Position (2,) and heading at time ``tq``; beyond the clip's end the path goes on
        with its final velocity and turn rate (a clip may end mid-stride)."""
        if tq > self.t[-1] and len(self.t) > 1:
            dt = tq - self.t[-1]
            h = self.t[-1] - self.t[-2]
            vel = (self.xz[-1] - self.xz[-2]) / h
            rate = (self.yaw[-1] - self.yaw[-2]) / h
            return self.xz[-1] + vel * dt, float(self.yaw[-1] + rate * dt)
        tq = max(float(tq), float(self.t[0]))
        xz = np.array([np.interp(tq, self.t, self.xz[:, 0]), np.interp(tq, self.t, self.xz[:, 1])])
        return xz, float(np.interp(tq, self.t, self.yaw))

    @classmethod
    def from_velocity(
        cls,
        t: np.ndarray,
        speed: np.ndarray,
        move_dir: np.ndarray | float,
        yaw: np.ndarray,
        fps: float,
        start: tuple[float, float] = (0.0, 0.0),
    ) -> RootPath:
        """Integrate a speed (m/s) along ``move_dir`` (rad, relative to the heading: 0 forward,
        pi backward, +pi/2 to the left) while the heading follows ``yaw``."""
        direction = yaw + np.broadcast_to(np.asarray(move_dir, dtype=np.float64), yaw.shape)
        fwd, _ = heading_vectors(direction)
        vel = speed[:, None] * fwd[:, [0, 2]]
        xz = integrate(vel, fps) + np.asarray(start)
        return cls(t=t, xz=xz, yaw=yaw)


@dataclass
class Gait:
    """How the feet move.

    Attributes:
        cadence: steps per second (both feet together), scalar or (T,).
        duty: fraction of a gait cycle each foot is planted (walk ~0.6, run ~0.35).
        width: lateral distance between the feet (m).
        clearance: swing lift of the ankle (m) for a full-length step.
        step_ref: step length (m) that gets the full heel-toe roll.
        strike: "heel" (walk) or "fore" (forefoot, running and jumping).
        heel_pitch, push_pitch, fore_pitch: roll angles (rad) at heel strike, push-off and
            forefoot strike for a full-length step.
        ref_frac: the foot lands where the path will be after this fraction of its stance.
        toe_out: outward turn of each foot (rad).
        first: the foot that steps first.
        start: time (s) the first swing may begin.
        min_move: swings moving a foot less than this (m) and turning it less than
            ``min_turn`` (rad) are skipped.
        min_width: the feet never get closer sideways than this (m).
        free_twist: a planted foot pivots on its ball when the heading turns further than
            this (rad) away from it.
    """

    cadence: float | np.ndarray = 1.9
    duty: float = 0.62
    width: float = 0.2
    clearance: float = 0.07
    step_ref: float = 0.7
    strike: str = "heel"
    heel_pitch: float = 0.3
    push_pitch: float = 0.85
    fore_pitch: float = 0.3
    ref_frac: float = 0.4
    toe_out: float = 0.08
    first: str = "left"
    start: float = 0.0
    min_move: float = 0.035
    min_turn: float = 0.12
    min_width: float = 0.12
    free_twist: float = 0.45


def plan_footholds(
    path: RootPath, gait: Gait, fps: float, initial: dict[str, tuple[np.ndarray, float]] | None = None
) -> dict[str, list[Stance]]:
    """Plan the stances of both feet along ``path``.

    Args:
        path: the root path (its times define the clip).
        gait: gait parameters.
        fps: frame rate of ``path.t``.
        initial: optional starting footholds {side: ((x, z), yaw)}; by default the feet
            stand beside the path's start.

    Returns:
        {"left": [...], "right": [...]}: stances in time order, the first starting at -inf
        and the last ending at +inf.
    """
    t = path.t
    t_end = float(t[-1])  # swings may land after the clip's end
    stances: dict[str, list[Stance]] = {}
    for side in ("left", "right"):
        if initial and side in initial:
            xz0, yaw0 = initial[side]
        else:
            xz0, yaw0 = _target(path, float(t[0]), side, gait.width, gait.toe_out)
        stances[side] = [
            Stance(t_on=-np.inf, t_off=np.inf, xz=np.asarray(xz0, dtype=np.float64), yaw=float(yaw0))
        ]

    for side, t0, t1 in _swing_windows(path, gait, fps):
        if t0 >= t_end:
            continue
        cur = stances[side][-1]
        if t0 <= cur.t_on:
            continue
        stance_time = _stance_time(gait, t1, t)
        xz, yaw = _target(path, t1 + gait.ref_frac * stance_time, side, gait.width, gait.toe_out)
        xz = _keep_apart(xz, yaw, side, stances, t1, gait.min_width)
        move = float(np.linalg.norm(xz - cur.xz))
        turn = abs(wrap_angle(yaw - cur.yaw))
        if move < gait.min_move and turn < gait.min_turn:
            continue
        _append_step(stances[side], side, t0, t1, xz, yaw, gait, stance_time)
    for side in ("left", "right"):
        for st in stances[side]:
            _add_pivot(st, path, side, gait)
    return stances


def _append_step(
    stances: list[Stance],
    side: str,
    t0: float,
    t1: float,
    xz: np.ndarray,
    yaw: float,
    gait: Gait,
    stance_time: float,
    ground: float = 0.0,
) -> Stance:
    """End the foot's current stance at ``t0`` (with its push-off roll) and add the stance that
    lands at ``t1`` on ``xz`` (heel or forefoot strike, swing clearance from the step length)."""
    cur = stances[-1]
    _roll(cur, xz, yaw, side, gait, t0, t1, stance_time)
    cur.t_off = t0
    nxt = Stance(t_on=t1, t_off=np.inf, xz=np.asarray(xz, dtype=np.float64), yaw=float(yaw), ground=ground)
    move = float(np.linalg.norm(nxt.xz - cur.xz))
    fwd = _forward_amount(cur, nxt.xz, yaw)
    ratio = min(abs(fwd) / gait.step_ref, 1.2)
    # Any real step lifts the toes clear of the floor (>= 7.5 cm at the ankle).
    nxt.clearance = max(
        gait.clearance * (0.55 + 0.45 * min(move / gait.step_ref, 1.0)), 0.075 if move > 0.1 else 0.05
    )
    if fwd >= 0 and gait.strike == "heel":
        nxt.land_pitch = gait.heel_pitch * ratio
    else:
        nxt.land_pitch = -gait.fore_pitch * max(ratio, 0.3 if gait.strike == "fore" else 0.0)
    nxt.land_time = min(0.12, 0.3 * stance_time)
    nxt.swing_shape = "run" if gait.strike == "fore" else "walk"
    nxt.lift_skew = float(np.clip(fwd / gait.step_ref, -1.0, 1.0))
    stances.append(nxt)
    return nxt


@dataclass
class Step:
    """One planned step: ``side`` lifts off at ``t_off`` and lands at ``t_on`` on ``xz`` (x, z),
    turned to ``yaw``, on a surface ``ground`` m high."""

    side: str
    t_off: float
    t_on: float
    xz: np.ndarray
    yaw: float
    ground: float = 0.0


def plan_steps(
    initial: dict[str, tuple[np.ndarray, float]],
    steps: list[Step],
    gait: Gait,
    ground: dict[str, float] | None = None,
) -> dict[str, list[Stance]]:
    """Stances of both feet from explicit steps (terrain: stairs, a platform, an obstacle),
    with the same heel-toe roll and swing clearance rules as :func:`plan_footholds`.

    Args:
        initial: starting footholds {side: ((x, z), yaw)}.
        steps: the steps in time order (each foot's own steps must not overlap).
        gait: roll angles, clearance and step length reference.
        ground: starting surface height of each foot (default 0).

    Returns:
        {"left": [...], "right": [...]}: stances in time order (first from -inf, last to +inf).
    """
    stances = {
        side: [
            Stance(
                t_on=-np.inf,
                t_off=np.inf,
                xz=np.asarray(initial[side][0], dtype=np.float64),
                yaw=float(initial[side][1]),
                ground=(ground or {}).get(side, 0.0),
            )
        ]
        for side in ("left", "right")
    }
    ordered = sorted(steps, key=lambda st: st.t_off)
    for k, step in enumerate(ordered):
        nxt = next((st for st in ordered[k + 1 :] if st.side == step.side), None)
        stance_time = (nxt.t_off - step.t_on) if nxt else 2.0 * gait.duty / float(np.mean(gait.cadence))
        _append_step(
            stances[step.side],
            step.side,
            step.t_off,
            step.t_on,
            step.xz,
            step.yaw,
            gait,
            stance_time,
            step.ground,
        )
    return stances


def _add_pivot(st: Stance, path: RootPath, side: str, gait: Gait) -> None:
    """Let a planted foot turn on its ball when the body turns more than ``gait.free_twist``
    away from it (sharp turns, turning on the spot), instead of twisting the leg."""
    t = path.t
    start = max(st.t_on + st.land_time if np.isfinite(st.t_on) else t[0], t[0])
    end = min(st.t_off, t[-1])
    if end <= start:
        return
    want = wrap_angle(path.yaw + SIDE_SIGN[side] * gait.toe_out - st.yaw)
    excess = np.sign(want) * np.maximum(np.abs(want) - gait.free_twist, 0.0)
    excess = np.where((t >= start) & (t <= end), excess, 0.0)
    if np.abs(excess).max() < 1e-3:
        return
    # Hold the pivot reached at lift-off so the swing starts from it.
    after = t > end
    excess[after] = float(np.interp(end, t, excess))
    st.pivot = (t.copy(), excess)


def _swing_windows(path: RootPath, gait: Gait, fps: float) -> list[tuple[str, float, float]]:
    """Candidate swings (side, lift-off time, touch-down time) from the gait clock."""
    fine = np.linspace(path.t[0], path.t[-1], (len(path.t) - 1) * 8 + 1)
    cad = np.interp(fine, path.t, np.broadcast_to(np.asarray(gait.cadence, dtype=np.float64), path.t.shape))
    phase = integrate(np.maximum(cad, 0.2) / 2.0, fps * 8)  # gait cycles
    start_phase = float(np.interp(gait.start, fine, phase))
    swing = 1.0 - gait.duty
    sides = (gait.first, "right" if gait.first == "left" else "left")
    out: list[tuple[str, float, float]] = []
    j = 0
    while True:
        p0 = start_phase + 0.5 * j
        if p0 > phase[-1]:
            return out
        t0 = float(np.interp(p0, phase, fine))
        t1 = _time_at(p0 + swing, phase, fine, float(cad[-1]))
        out.append((sides[j % 2], t0, t1))
        j += 1


def _time_at(p: float, phase: np.ndarray, fine: np.ndarray, last_cadence: float) -> float:
    """Time at gait phase ``p``, extrapolated past the clip with the last cadence."""
    if p <= phase[-1]:
        return float(np.interp(p, phase, fine))
    return float(fine[-1] + (p - phase[-1]) * 2.0 / max(last_cadence, 0.2))


def _stance_time(gait: Gait, t1: float, t: np.ndarray) -> float:
    cad = float(np.interp(t1, t, np.broadcast_to(np.asarray(gait.cadence, dtype=np.float64), t.shape)))
    return 2.0 * gait.duty / max(cad, 0.2)


def _target(path: RootPath, tq: float, side: str, width: float, toe_out: float) -> tuple[np.ndarray, float]:
    xz, yaw = path.at(tq)
    _, left = heading_vectors(np.array(yaw))
    return xz + SIDE_SIGN[side] * 0.5 * width * left[[0, 2]], yaw + SIDE_SIGN[side] * toe_out


def _keep_apart(
    xz: np.ndarray, yaw: float, side: str, stances: dict[str, list[Stance]], t1: float, min_width: float
) -> np.ndarray:
    other = "right" if side == "left" else "left"
    planted = [s for s in stances[other] if s.t_on <= t1]
    if not planted:
        return xz
    _, left = heading_vectors(np.array(yaw - SIDE_SIGN[side] * 0.0))
    lat = float((xz - planted[-1].xz) @ left[[0, 2]]) * SIDE_SIGN[side]
    if lat < min_width:
        xz = xz + SIDE_SIGN[side] * (min_width - lat) * left[[0, 2]]
    return xz


def _forward_amount(cur: Stance, xz: np.ndarray, yaw: float) -> float:
    fwd, _ = heading_vectors(np.array(yaw))
    return float((xz - cur.xz) @ fwd[[0, 2]])


def _roll(
    cur: Stance, xz: np.ndarray, yaw: float, side: str, gait: Gait, t0: float, t1: float, stance_time: float
) -> None:
    """Set the lift-off roll of the stance that ends at ``t0`` from the coming step."""
    fwd = _forward_amount(cur, xz, yaw)
    ratio = min(abs(fwd) / gait.step_ref, 1.2)
    if fwd >= 0:
        cur.lift_pitch = -gait.push_pitch * max(ratio, 0.15)
    else:
        cur.lift_pitch = 0.5 * gait.heel_pitch * ratio
    prev_len = t0 - cur.t_on if np.isfinite(cur.t_on) else stance_time
    cur.lift_time = max(0.05, min(0.45 * stance_time, 0.5 * prev_len, 0.3))
