"""Feet: a rigid foot (ankle, toe, heel) that rolls over the heel or the toe while planted,
and swings between footholds.

A foot's trajectory is a list of :class:`Stance` (planted intervals). While planted, the
foot only rotates about its heel (pitch > 0, toe up: heel strike) or about its toe joint
(pitch < 0, heel up: push-off, tucked toes when kneeling); the pivot never moves, so a
planted foot never slides. Between two stances the foot swings on a minimum-jerk path
lifted by the landing stance's ``clearance``, never dipping below the floor.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from controlmm.corpus.curves import minjerk, ramp, smoothstep, wrap_angle
from controlmm.corpus.rig import FOOT, apply, rot_x, rot_y

TOE_HEIGHT = 0.008
"""Height (m) of the toe joint above the floor when the foot is flat."""
ANKLE_HEIGHT = 0.055
"""Height (m) of the ankle joint above the floor when the foot is flat."""
HEEL_BACK = 0.05
"""The heel's contact point lies this far (m) behind the ankle, on the floor."""


def toe_local(side: str) -> np.ndarray:
    """Ankle -> toe vector of a flat foot in the foot frame (x left, y up, z toes), (3,)."""
    drop = ANKLE_HEIGHT - TOE_HEIGHT
    return np.array([0.0, -drop, np.sqrt(FOOT[side] ** 2 - drop**2)])


HEEL_LOCAL = np.array([0.0, -ANKLE_HEIGHT, -HEEL_BACK])
"""Ankle -> heel contact point of a flat foot in the foot frame, (3,)."""

Terrain = Callable[[np.ndarray], np.ndarray]
"""Ground height (m) under ground points: (N, 2) as (x, z) -> (N,); the flat floor is 0."""


def foot_frame(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Foot orientation (..., 3, 3): heading ``yaw``, then ``pitch`` (> 0 lifts the toes)."""
    return rot_y(yaw) @ rot_x(-np.asarray(pitch, dtype=np.float64))


def ankle_from_pivot(side: str, flat_ankle: np.ndarray, yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Ankle positions (T, 3) of a planted foot rolled by ``pitch`` about its heel (pitch > 0)
    or its toe joint (pitch < 0); ``flat_ankle`` (3,) is the ankle of the flat foot."""
    pitch = np.asarray(pitch, dtype=np.float64)
    yaw = np.broadcast_to(np.asarray(yaw, dtype=np.float64), pitch.shape)
    pivot_local = np.where(pitch[:, None] >= 0.0, HEEL_LOCAL, toe_local(side))
    flat = foot_frame(yaw, np.zeros_like(pitch))
    pivot_world = flat_ankle + apply(flat, pivot_local)
    return pivot_world - apply(foot_frame(yaw, pitch), pivot_local)


def toe_position(side: str, ankle: np.ndarray, yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Toe joint positions (T, 3) from ankle, yaw and pitch."""
    return ankle + apply(foot_frame(yaw, pitch), toe_local(side))


def heel_position(ankle: np.ndarray, yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Heel contact points (T, 3) from ankle, yaw and pitch."""
    return ankle + apply(foot_frame(yaw, pitch), HEEL_LOCAL)


@dataclass
class Stance:
    """A planted interval of one foot.

    Attributes:
        t_on, t_off: landing and lift-off times (s); -inf / +inf for the first / last stance.
        xz: (2,) ground position (x, z) of the flat foot's ankle.
        yaw: foot heading (rad).
        land_pitch: foot pitch at touch-down (> 0 heel strike, < 0 toe strike), easing to 0
            over ``land_time`` seconds.
        lift_pitch: foot pitch at lift-off (< 0 push-off over the toe, > 0 over the heel),
            reached from 0 over the last ``lift_time`` seconds.
        clearance: height (m) the ankle is lifted by in the swing that lands here.
        swing_shape: "walk" (lift, travel, set down: a boxy path close to the floor) or
            "run" (the heel kicks up behind early, the foot travels on a high arc).
        lift_skew: for "walk" swings, +1 lifts the foot most early in the swing (the heel
            kicks up behind after a forward step), -1 late (a backward step), 0 evenly.
        pitch_keys: extra (time, pitch) keyframes added inside the stance (e.g. toes tucked
            while kneeling), eased with minimum jerk.
        pivot: optional (times, yaw offsets): the planted foot turns on the ball of the foot
            (about its toe joint, which stays put) by these offsets, e.g. to follow the body
            through a sharp turn. Zero while the heel is down after a heel strike.
        ground: height (m) of the surface the foot stands on (a step, a platform; 0 = floor).
        swing_keys: optional (times (K,), ankle positions (K, 3), pitches (K,)): the swing that
            lands here passes through these keys (a kick's chamber and extension) on a smooth
            spline that starts and ends at rest, instead of the lift-travel-set-down path.
    """

    t_on: float
    t_off: float
    xz: np.ndarray
    yaw: float
    land_pitch: float = 0.0
    land_time: float = 0.12
    lift_pitch: float = 0.0
    lift_time: float = 0.15
    clearance: float = 0.08
    swing_shape: str = "walk"
    lift_skew: float = 0.0
    pitch_keys: list[tuple[float, float]] = field(default_factory=list)
    pivot: tuple[np.ndarray, np.ndarray] | None = None
    ground: float = 0.0
    swing_keys: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def pitch(self, t: np.ndarray) -> np.ndarray:
        """Foot pitch (rad) at times ``t`` inside the stance."""
        t = np.asarray(t, dtype=np.float64)
        p = np.zeros_like(t)
        if np.isfinite(self.t_on) and self.land_pitch:
            p += self.land_pitch * (1.0 - ramp(t, self.t_on, self.t_on + self.land_time))
        if np.isfinite(self.t_off) and self.lift_pitch:
            p += self.lift_pitch * ramp(t, self.t_off - self.lift_time, self.t_off)
        if self.pitch_keys:
            times = [k[0] for k in self.pitch_keys]
            vals = [k[1] for k in self.pitch_keys]
            extra = np.zeros_like(t)
            prev_t, prev_v = times[0], 0.0
            for kt, kv in zip(times, vals, strict=True):
                extra = np.where(t >= prev_t, prev_v + (kv - prev_v) * ramp(t, prev_t, kt), extra)
                prev_t, prev_v = kt, kv
            p += extra
        return p

    def yaw_at(self, t: np.ndarray) -> np.ndarray:
        """Foot heading (rad) at times ``t`` inside the stance."""
        t = np.asarray(t, dtype=np.float64)
        if self.pivot is None:
            return np.full(t.shape, self.yaw)
        return self.yaw + np.interp(t, self.pivot[0], self.pivot[1])

    def ankle(self, side: str, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ankle positions (T, 3) and pitch (T,) at times ``t`` inside the stance."""
        pitch = self.pitch(t)
        flat = np.array([self.xz[0], ANKLE_HEIGHT + self.ground, self.xz[1]])
        ankle = ankle_from_pivot(side, flat, np.full(len(pitch), self.yaw), pitch)
        if self.pivot is not None:
            yaw = self.yaw_at(t)
            toe = flat + apply(foot_frame(np.array(self.yaw), np.array(0.0)), toe_local(side))
            turned = toe - apply(foot_frame(yaw, np.minimum(pitch, 0.0)), toe_local(side))
            ankle = np.where((yaw != self.yaw)[:, None], turned, ankle)
        return ankle, pitch


@dataclass
class FootTrack:
    """Per-frame trajectory of one foot: ankle (T, 3), yaw (T,), pitch (T,), planted (T,)."""

    ankle: np.ndarray
    yaw: np.ndarray
    pitch: np.ndarray
    planted: np.ndarray
    stances: list[Stance]


def foot_track(
    side: str, stances: list[Stance], t: np.ndarray, terrain: Terrain | None = None, clear: float = 0.0
) -> FootTrack:
    """Sample a foot's stances and the swings between them at times ``t`` (T,).

    ``terrain`` (ground height under a point; default the flat floor) is what swings must
    clear: a swing over a step or an obstacle is lifted until its toe and heel pass ``clear`` m
    above it in mid-swing (the margin shrinks to 0 at lift-off and touch-down)."""
    t = np.asarray(t, dtype=np.float64)
    n = len(t)
    ankle = np.zeros((n, 3))
    yaw = np.zeros(n)
    pitch = np.zeros(n)
    planted = np.zeros(n, dtype=bool)
    for k, st in enumerate(stances):
        m = (t >= st.t_on) & (t <= st.t_off)
        if m.any():
            a, p = st.ankle(side, t[m])
            ankle[m], pitch[m], yaw[m], planted[m] = a, p, st.yaw_at(t[m]), True
        if k + 1 < len(stances):
            nxt = stances[k + 1]
            m = (t > st.t_off) & (t < nxt.t_on)
            if m.any():
                a, y, p = _swing(side, st, nxt, t[m], terrain, clear)
                ankle[m], yaw[m], pitch[m] = a, y, p
    return FootTrack(ankle=ankle, yaw=yaw, pitch=pitch, planted=planted, stances=stances)


def _swing(
    side: str, a: Stance, b: Stance, t: np.ndarray, terrain: Terrain | None = None, clear: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t0, t1 = a.t_off, b.t_on
    s = (t - t0) / (t1 - t0)
    a0, p0 = a.ankle(side, np.array([t0]))
    a1, p1 = b.ankle(side, np.array([t1]))
    a0, a1, p0, p1 = a0[0], a1[0], p0[0], p1[0]
    y0 = float(a.yaw_at(np.array([t0]))[0])
    yaw = y0 + wrap_angle(b.yaw - y0) * minjerk(s)
    if b.swing_keys is not None:
        key_t, key_pos, key_pitch = b.swing_keys
        knots = np.concatenate([[t0], np.asarray(key_t, dtype=np.float64), [t1]])
        path = CubicSpline(knots, np.concatenate([a0[None], key_pos, a1[None]]), bc_type="clamped")
        roll = CubicSpline(knots, np.concatenate([[p0], key_pitch, [p1]]), bc_type="clamped")
        return path(t), yaw, roll(t)
    pitch = p0 + (p1 - p0) * smoothstep((s - 0.15) / 0.8)
    clearance = b.clearance
    margin = clear * np.sin(np.pi * np.clip(s, 0.0, 1.0))
    for _ in range(6):
        ankle = _swing_path(a0, a1, s, a, b, clearance)
        short = _shortfall(side, ankle, yaw, pitch, terrain, margin)
        if terrain is None or short.max() < 1e-3:
            break
        # Lift the whole arc (not just the frames that touch) so the foot clears the obstacle smoothly.
        lift = np.maximum(_lift(s, b), 0.2)
        clearance += float((short / lift).max()) + 0.01
    # Never below the ground: raise the ankle until toe and heel clear it.
    ankle[:, 1] += _shortfall(side, ankle, yaw, pitch, terrain)
    return ankle, yaw, pitch


def _lift(s: np.ndarray, b: Stance) -> np.ndarray:
    """Height profile (0 at both ends) of the swing that lands on ``b``, peak about 1."""
    if b.swing_shape == "jump":
        return 4.0 * s * (1.0 - s)
    if b.swing_shape == "run":
        return np.sin(np.pi * np.clip(s, 0.0, 1.0) ** 0.75)
    # The heel kicks up early in the swing (knee flexion), the foot skims lower later.
    return np.sin(np.pi * np.clip(s, 0.0, 1.0)) ** 0.6 * (1.0 + 0.5 * b.lift_skew * (1.0 - 2.0 * s))


def _swing_path(
    a0: np.ndarray, a1: np.ndarray, s: np.ndarray, a: Stance, b: Stance, clearance: float
) -> np.ndarray:
    """Ankle positions (T, 3) of a swing from ``a0`` (leaving stance ``a``) to ``a1`` (landing on
    stance ``b``) at progress ``s``."""
    if b.swing_shape == "jump":
        w = minjerk(s)[:, None]
    else:
        # Walking and running: the foot leaves and lands at rest but travels with a peak speed of
        # 1.5 x its mean (smoothstep), as measured swing feet do (gait data put the peak at
        # 1.4-1.5 x stride / swing time); the minimum-jerk profile's 1.875 x made the swing foot
        # of a 1 m/s walk peak near 6-7 m/s.
        w = smoothstep(s)[:, None]
    ankle = a0 + w * (a1 - a0)
    step = b.ground - a.ground
    if step > 0.02:  # up a step: rise early, then travel over the edge
        base = smoothstep(s / 0.6)
    elif step < -0.02:  # down a step: clear the edge first, drop late
        base = smoothstep((s - 0.4) / 0.6)
    else:
        base = smoothstep(s)
    ankle[:, 1] = a0[1] + base * (a1[1] - a0[1]) + clearance * _lift(s, b)
    return ankle


def _shortfall(
    side: str,
    ankle: np.ndarray,
    yaw: np.ndarray,
    pitch: np.ndarray,
    terrain: Terrain | None,
    margin: np.ndarray | float = 0.0,
) -> np.ndarray:
    """How far (m, >= 0) the foot (toe joint, heel) dips below the ground + ``margin`` per frame."""
    toe = toe_position(side, ankle, yaw, pitch)
    heel = heel_position(ankle, yaw, pitch)
    g_toe = np.zeros(len(toe)) if terrain is None else terrain(toe[:, [0, 2]])
    g_heel = np.zeros(len(heel)) if terrain is None else terrain(heel[:, [0, 2]])
    return np.maximum(0.0, np.maximum(TOE_HEIGHT + g_toe - toe[:, 1], g_heel - heel[:, 1]) + margin)


def swing_bump(tracks: dict[str, FootTrack], t: np.ndarray) -> np.ndarray:
    """sin(pi s) over every swing of either foot (s = progress through the swing), 0 while
    both feet are planted: peaks when the swinging foot passes the planted one (mid-stance),
    the moment a walker's pelvis is highest."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(t)
    for track in tracks.values():
        for a, b in zip(track.stances[:-1], track.stances[1:], strict=True):
            s = (t - a.t_off) / (b.t_on - a.t_off)
            inside = (s > 0.0) & (s < 1.0)
            out[inside] += np.sin(np.pi * s[inside])
    return out


def stance_bump(tracks: dict[str, FootTrack], t: np.ndarray, max_stance: float = 0.6) -> np.ndarray:
    """sin(pi s) over every finite stance shorter than ``max_stance`` seconds (s = progress
    through the stance): peaks at a runner's mid-stance, when the leg is most compressed."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(t)
    for track in tracks.values():
        for st in track.stances:
            if not (np.isfinite(st.t_on) and np.isfinite(st.t_off)) or st.t_off - st.t_on > max_stance:
                continue
            s = (t - st.t_on) / (st.t_off - st.t_on)
            inside = (s > 0.0) & (s < 1.0)
            out[inside] += np.sin(np.pi * s[inside])
    return out
