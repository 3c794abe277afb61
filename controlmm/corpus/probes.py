"""Text-adherence probes: does a motion do what its caption says?

Each motion family has a probe that checks, with simple geometry in the person's own frame
(:mod:`controlmm.motion.geometry`), the family's core property and every *claim* a caption
makes (direction, speed, hand, count, turn angle...). A claim comes from the caption's
metadata (``meta/<id>.json`` of a corpus), so the same probe checks ground truth and
generated motion:

    cases = list_cases("corpus", split="test")     # ProbeCase per caption (controlmm.eval.cases)
    result = check(cases[0], motion)               # ProbeResult(passed, value, checks)

Thresholds are loose enough that every corpus clip passes and tight enough that a motion
made for another caption of the same kind (left vs right hand, clockwise vs counter-
clockwise, forward vs backward, two vs three jumps) fails.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controlmm.corpus.measures import Measures
from controlmm.errors import ControlMMError
from controlmm.motion import geometry as geo
from controlmm.motion.container import Motion

__all__ = ["PROBES", "Check", "ProbeCase", "ProbeResult", "check", "probe"]

HANDS = {"left": (20, 16), "right": (21, 17)}  # wrist, shoulder
KNEES = {"left": 4, "right": 5}
HEAD, PELVIS, CHEST = 15, 0, 9


@dataclass(frozen=True)
class ProbeCase:
    """A caption of a clip with what it claims: the input of a probe."""

    clip_id: str
    caption: str
    family: str
    claims: dict[str, Any]
    frames: int
    split: str
    template: str = ""
    held_out: bool = False
    params: dict[str, Any] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Check:
    """One measured property: its name, the measured value, whether it passed, the rule."""

    name: str
    value: float
    passed: bool
    rule: str


@dataclass(frozen=True)
class ProbeResult:
    """Outcome of a probe: passed when every check passed; ``value`` is the first check's."""

    family: str
    checks: tuple[Check, ...]

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def value(self) -> float:
        return self.checks[0].value if self.checks else float("nan")

    def failures(self) -> list[Check]:
        return [c for c in self.checks if not c.passed]

    def describe(self) -> str:
        return "; ".join(
            f"{c.name}={c.value:.3g} ({'ok' if c.passed else 'FAIL'}: {c.rule})" for c in self.checks
        )


def _c(name: str, value: float, ok: bool, rule: str) -> Check:
    return Check(name, float(value), bool(ok), rule)


def _sign(direction: str) -> float:
    return 1.0 if direction == "left" else -1.0


# --- shared checks --------------------------------------------------------------------------


def _forward_travel(m: Measures, minimum: float) -> list[Check]:
    fwd, _, length = m.travel
    return [
        _c("forward_travel_m", fwd, fwd >= minimum, f">= {minimum} m along the facing direction"),
        _c("forward_share", fwd / max(length, 1e-6), fwd >= 0.75 * length, ">= 0.75 of the path"),
    ]


def _speed_band(m: Measures, lo: float, hi: float, name: str = "cruise_speed") -> Check:
    return _c(name, m.cruise, lo <= m.cruise <= hi, f"in [{lo}, {hi}] m/s")


def _speed_claim(m: Measures, claims: dict) -> list[Check]:
    bands = {"slow": (0.0, 1.0), "normal": (0.85, 1.6), "fast": (1.45, 2.3)}
    if "speed" not in claims:
        return []
    lo, hi = bands[claims["speed"]]
    return [_speed_band(m, lo, hi, f"{claims['speed']}_speed")]


def _turn_checks(m: Measures, claims: dict, minimum: float = 45.0) -> list[Check]:
    checks = []
    if "direction" in claims:
        s = _sign(claims["direction"])
        checks.append(
            _c(
                "turn_deg",
                m.turn,
                s * m.turn >= minimum,
                f"{'+' if s > 0 else '-'}{minimum} deg or more "
                f"({claims['direction']} is {'+' if s > 0 else '-'})",
            )
        )
    if "angle" in claims:
        a = float(claims["angle"])
        lo, hi = 0.7 * a - 10.0, 1.3 * a + 10.0
        checks.append(
            _c("turn_size_deg", abs(m.turn), lo <= abs(m.turn) <= hi, f"|turn| in [{lo:.0f}, {hi:.0f}]")
        )
    if not checks:
        checks.append(_c("turn_size_deg", abs(m.turn), abs(m.turn) >= minimum, f"|turn| >= {minimum}"))
    return checks


def _wave_checks(m: Measures, hand: str) -> list[Check]:
    wrist, _ = HANDS[hand]
    other, _ = HANDS["right" if hand == "left" else "left"]
    high = m.above(wrist, HEAD) > 0.05
    lateral = m.body(wrist)[:, 0]
    swings = geo.oscillations(lateral[high], 0.06) if high.sum() > 3 else 0
    return [
        _c(
            f"{hand}_wrist_above_head_frames",
            high.sum(),
            high.sum() >= 15,
            ">= 15 frames 5 cm above the head",
        ),
        _c(f"{hand}_wrist_swings", swings, swings >= 3, ">= 3 side-to-side swings of 6 cm while raised"),
        _c(
            "other_wrist_above_head_m",
            m.above(other, HEAD).max(),
            m.above(other, HEAD).max() < 0.0,
            "the other wrist stays below the head",
        ),
    ]


def _count_check(name: str, counted: int, claims: dict) -> list[Check]:
    want = int(claims["count"])
    return [_c(name, counted, counted == want, f"== {want}")]


def _squat_dips(m: Measures, start: int = 0) -> int:
    y = m.pelvis_height[start:]
    stand = np.percentile(m.pelvis_height, 95)
    return geo.count_dips(y, stand - 0.2, stand - 0.08)


# --- family probes ------------------------------------------------------------------------


def _walk(m, c):
    return (
        _forward_travel(m, 0.5)
        + [
            _speed_band(m, 0.4, 2.0),
            _c(
                "flight_frames",
                sum(b - a for a, b in m.flights),
                sum(b - a for a, b in m.flights) < 3,
                "< 3 (a foot always down)",
            ),
        ]
        + _speed_claim(m, c)
    )


def _jog(m, c):
    return _forward_travel(m, 1.0) + [_speed_band(m, 1.7, 3.1)]


def _run(m, c):
    return _forward_travel(m, 1.5) + [_speed_band(m, 2.8, 6.0)]


def _backward(m, c):
    fwd, _, length = m.travel
    return [
        _c("backward_travel_m", -fwd, -fwd >= 0.5, ">= 0.5 m against the facing direction"),
        _c("backward_share", -fwd / max(length, 1e-6), -fwd >= 0.75 * length, ">= 0.75 of the path"),
    ]


def _sidestep(m, c):
    s = _sign(c["direction"])
    fwd, left, length = m.travel
    return [
        _c("sideways_travel_m", s * left, s * left >= 0.4, f">= 0.4 m to the {c['direction']}"),
        _c(
            "sideways_share",
            abs(left) / max(length, 1e-6),
            abs(left) >= 2 * abs(fwd),
            "|left| >= 2 |forward|",
        ),
        _c("turn_deg", m.turn, abs(m.turn) <= 45.0, "|turn| <= 45 (keeps facing the same way)"),
    ]


def _crouch_walk(m, c):
    moving = np.concatenate([[False], m.speed > 0.25])
    low = float(np.median(m.pelvis_height[moving])) if moving.any() else float(m.pelvis_height.mean())
    return _forward_travel(m, 0.5) + [_c("pelvis_height_moving_m", low, low <= 0.8, "<= 0.8 m (crouched)")]


def _stop_and_go(m, c):
    v = m.speed
    still = geo.segments(v < 0.15, min_len=10)
    dist = np.concatenate([[0.0], np.cumsum(v / m.fps)])
    best = 0.0
    for a, b in still:
        before, after = dist[a], dist[-1] - dist[b]
        best = max(best, min(before, after))
    return _forward_travel(m, 1.0) + [
        _c("walk_around_stop_m", best, best >= 0.5, ">= 0.5 m before and after a stop of >= 0.5 s")
    ]


def _walk_to_point(m, c):
    fwd, left = m.displacement()
    dist = float(np.hypot(fwd, left))
    bearing = float(np.degrees(np.arctan2(left, fwd)))
    checks = [_c("final_speed", m.speed[-10:].mean(), m.speed[-10:].mean() < 0.2, "< 0.2 m/s (stopped)")]
    if "meters" in c:
        k = float(c["meters"])
        checks.append(_c("distance_m", dist, abs(dist - k) <= 0.6, f"within 0.6 m of {k:g} m"))
    where = c.get("where")
    if where == "ahead":
        checks.append(_c("bearing_deg", bearing, abs(bearing) <= 15.0, "|bearing| <= 15"))
    elif where in ("left", "right"):
        s = _sign(where)
        checks.append(
            _c("bearing_deg", bearing, 15.0 <= s * bearing <= 80.0, f"{where}: {'+' if s > 0 else '-'}15..80")
        )
    return checks


def _turn_in_place(m, c):
    fwd, left = m.displacement()
    return _turn_checks(m, c) + [
        _c("displacement_m", np.hypot(fwd, left), np.hypot(fwd, left) <= 0.5, "<= 0.5 m (in place)")
    ]


def _circle(m, c):
    s = 1.0 if c["rotation"] == "counterclockwise" else -1.0
    return [
        _c(
            "turn_deg",
            m.turn,
            s * m.turn >= 300.0,
            f"{'+' if s > 0 else '-'}300 deg or more ({c['rotation']} is {'+' if s > 0 else '-'})",
        ),
        _c("path_m", m.travel[2], m.travel[2] >= 3.0, ">= 3 m"),
    ]


def _curve(m, c):
    s = _sign(c["direction"])
    return [
        _c("turn_deg", m.turn, 30.0 <= s * m.turn <= 240.0, f"{'+' if s > 0 else '-'}30..240 deg"),
        *_forward_travel(m, 1.0),
    ]


def _zigzag(m, c):
    h = m.heading
    swings = geo.oscillations(h - np.linspace(h[0], h[-1], len(h)), 30.0)
    fwd, _ = m.displacement()
    return [
        _c("heading_swings", swings, swings >= 2, ">= 2 heading swings of 30 deg"),
        _c("net_turn_deg", m.turn, abs(m.turn) <= 75.0, "|net turn| <= 75"),
        _c("progress_m", fwd, fwd >= 1.5, ">= 1.5 m forward of the start"),
    ]


def _jump_in_place(m, c):
    fwd, left = m.displacement()
    return _count_check("flights", len(m.flights), c) + [
        _c("displacement_m", np.hypot(fwd, left), np.hypot(fwd, left) <= 0.4, "<= 0.4 m (in place)")
    ]


def _jump_forward(m, c):
    fwd, _ = m.displacement()
    n = int(c.get("count", 1))
    return _count_check("flights", len(m.flights), c) + [
        _c("forward_m", fwd, fwd >= 0.3 * n, f">= {0.3 * n:.1f} m forward")
    ]


def _squat(m, c):
    return _count_check("squats", _squat_dips(m), c)


def _kneel(m, c):
    knee = KNEES[c["knee"]]
    other = KNEES["right" if c["knee"] == "left" else "left"]
    low, other_low = m.j[:, knee, 1].min(), m.j[:, other, 1].min()
    checks = [
        _c(f"{c['knee']}_knee_min_m", low, low <= 0.12, "<= 0.12 m (on the floor)"),
        _c("other_knee_min_m", other_low, other_low >= 0.2, ">= 0.2 m (the other knee up)"),
    ]
    if c.get("stand_up") is True:
        checks.append(
            _c("final_pelvis_m", m.pelvis_height[-1], m.pelvis_height[-1] >= 0.8, ">= 0.8 m (standing)")
        )
    elif c.get("stand_up") is False:
        checks.append(
            _c("final_pelvis_m", m.pelvis_height[-1], m.pelvis_height[-1] <= 0.65, "<= 0.65 m (kneeling)")
        )
    return checks


def _wave(m, c):
    return _wave_checks(m, c.get("hand", "left"))


def _raise_arm(m, c):
    hands = ("left", "right") if c["hand"] == "both" else (c["hand"],)
    checks = []
    if len(hands) == 2:
        both = np.minimum(m.above(20, HEAD), m.above(21, HEAD))
        checks.append(
            _c("both_wrists_above_head_m", both.max(), both.max() >= 0.15, ">= 0.15 m, both at once")
        )
    else:
        wrist, _ = HANDS[hands[0]]
        other, shoulder = HANDS["right" if hands[0] == "left" else "left"]
        checks.append(
            _c(
                f"{hands[0]}_wrist_above_head_m",
                m.above(wrist, HEAD).max(),
                m.above(wrist, HEAD).max() >= 0.15,
                ">= 0.15 m",
            )
        )
        checks.append(
            _c(
                "other_wrist_above_shoulder_m",
                m.above(other, shoulder).max(),
                m.above(other, shoulder).max() < 0.0,
                "< 0 (the other arm stays down)",
            )
        )
    return checks


def _reach_forward(m, c):
    wrist, _ = HANDS[c["hand"]]
    other, _ = HANDS["right" if c["hand"] == "left" else "left"]
    ahead, other_ahead = m.body(wrist)[:, 2].max(), m.body(other)[:, 2].max()
    return [
        _c(f"{c['hand']}_wrist_forward_m", ahead, ahead >= 0.45, ">= 0.45 m in front of the pelvis"),
        _c("other_wrist_forward_m", other_ahead, other_ahead < 0.3, "< 0.3 m"),
    ]


def _reach_up(m, c):
    return _raise_arm(m, c)


def _reach_sideways(m, c):
    s = _sign(c["hand"])
    wrist, _ = HANDS[c["hand"]]
    other, _ = HANDS["right" if c["hand"] == "left" else "left"]
    out, other_out = (s * m.body(wrist)[:, 0]).max(), (-s * m.body(other)[:, 0]).max()
    return [
        _c(f"{c['hand']}_wrist_sideways_m", out, out >= 0.6, f">= 0.6 m to the {c['hand']} of the pelvis"),
        _c("other_wrist_sideways_m", other_out, other_out < 0.4, "< 0.4 m"),
    ]


def _punch(m, c):
    wrist, _ = HANDS[c["hand"]]
    other, _ = HANDS["right" if c["hand"] == "left" else "left"]
    reach = m.body(wrist, CHEST)[:, 2]
    punches = geo.count_dips(-reach, -0.42, -0.32)
    other_reach = m.body(other, CHEST)[:, 2].max()
    return _count_check("punches", punches, c) + [
        _c("other_wrist_forward_m", other_reach, other_reach < 0.36, "< 0.36 m in front of the chest")
    ]


def _clap(m, c):
    gap = np.linalg.norm(m.j[:, 20] - m.j[:, 21], axis=-1)
    claps = geo.count_dips(gap, 0.12, 0.22)
    front = np.minimum(m.body(20, CHEST)[:, 2], m.body(21, CHEST)[:, 2])[gap < 0.12]
    ahead = float(front.min()) if len(front) else 0.0
    return _count_check("claps", claps, c) + [
        _c("clap_in_front_m", ahead, ahead >= 0.15, ">= 0.15 m in front of the chest")
    ]


def _walk_and_wave(m, c):
    return _forward_travel(m, 1.0) + _wave_checks(m, c["hand"])


def _turn_then_walk(m, c):
    h = m.heading
    total = m.turn
    done = int(np.argmax(np.abs(h - h[0]) >= 0.9 * abs(total))) if abs(total) > 1 else 0
    fwd, _ = m.displacement(start=min(done, len(h) - 2))
    return _turn_checks(m, c) + [_c("walk_after_turn_m", fwd, fwd >= 1.0, ">= 1 m along the new facing")]


def _walk_then_squat(m, c):
    dips = _squat_dips(m)
    low = int(np.argmin(m.pelvis_height))
    fwd, _ = m.displacement(0, low)
    still = m.speed[max(low - 3, 0) : low + 3].mean()
    return _count_check("squats", dips, c) + [
        _c("walk_before_m", fwd, fwd >= 1.0, ">= 1 m forward before squatting"),
        _c("speed_at_squat", still, still < 0.25, "< 0.25 m/s (stopped to squat)"),
    ]


# --- postures ---------------------------------------------------------------------------


def _longest(mask: np.ndarray) -> int:
    runs = geo.segments(mask)
    return max((b - a for a, b in runs), default=0)


def _ankles_ahead(m: Measures) -> np.ndarray:
    """How far (m, T) the ankles' midpoint lies ahead of the pelvis along the facing."""
    return 0.5 * (m.body(7)[:, 2] + m.body(8)[:, 2])


def _seated(m: Measures) -> np.ndarray:
    """Frames sitting on a seat: pelvis lowered >= 15 cm, the feet >= 22 cm in front of it, the
    trunk upright (<= 30 deg)."""
    return (m.pelvis_height <= m.stand_height - 0.15) & (_ankles_ahead(m) >= 0.22) & (m.trunk_pitch <= 30.0)


def _end_checks(m: Measures, c: dict, down: str, low: float) -> list[Check]:
    """``stand_up`` claims: back at standing height at the end, or still down (pelvis <= ``low``)."""
    end = float(m.pelvis_height[-3:].mean())
    if c.get("stand_up") is True:
        top = m.stand_height - 0.08
        return [_c("final_pelvis_m", end, end >= top, f">= {top:.2f} m (standing again)")]
    if c.get("stand_up") is False:
        return [_c("final_pelvis_m", end, end <= low, f"<= {low:.2f} m (still {down})")]
    return []


def _sit_down(m, c):
    seated = _seated(m)
    run = _longest(seated)
    checks = [_c("seated_frames", run, run >= 15, ">= 15 frames seated (pelvis down, feet ahead, trunk up)")]
    checks += _end_checks(m, c, "seated", m.stand_height - 0.15)
    if c.get("stand_up") is False:
        checks.append(
            _c("seated_at_end", float(seated[-3:].all()), bool(seated[-3:].all()), "seated at the end")
        )
    return checks


def _lie_down(m, c):
    lying = (m.pelvis_height <= 0.3) & (m.trunk_pitch <= -60.0)
    run = _longest(lying)
    return [
        _c(
            "lying_frames",
            run,
            run >= 8,
            ">= 8 frames lying on the back (pelvis <= 0.3 m, trunk >= 60 deg back)",
        )
    ] + _end_checks(m, c, "lying", 0.3)


def _bow_count(m: Measures) -> int:
    return geo.count_dips(-m.trunk_pitch, -25.0, -12.0)


def _bow(m, c):
    dip = m.stand_height - float(m.pelvis_height.min())
    checks = [_c("pelvis_dip_m", dip, dip <= 0.15, "<= 0.15 m (bending at the hips, not the knees)")]
    if "count" in c:
        return _count_check("bows", _bow_count(m), c) + checks
    n = _bow_count(m)
    return [_c("bows", n, n >= 1, ">= 1 forward bend of the trunk past 25 deg")] + checks


def _pick_up(m, c):
    low = float(m.j[:, [20, 21], 1].min())
    dip = m.stand_height - float(m.pelvis_height.min())
    fwd, left = m.displacement()
    checks = [
        _c("wrist_min_height_m", low, low <= 0.35, "<= 0.35 m (a hand down at the floor)"),
        _c("displacement_m", np.hypot(fwd, left), np.hypot(fwd, left) <= 0.5, "<= 0.5 m (in place)"),
    ]
    checks += _end_checks(m, {"stand_up": True}, "", 0.0)
    if c.get("style") == "squat":
        checks.append(_c("pelvis_dip_m", dip, dip >= 0.38, ">= 0.38 m (squatting)"))
    elif c.get("style") == "stoop":
        top = float(m.trunk_pitch.max())
        checks.append(_c("pelvis_dip_m", dip, dip < 0.38, "< 0.38 m (not a squat)"))
        checks.append(_c("trunk_pitch_deg", top, top >= 65.0, ">= 65 deg (bending over)"))
    return checks


# --- actions ----------------------------------------------------------------------------

ANKLES = {"left": 7, "right": 8}


def _kick_checks(m: Measures, c: dict) -> list[Check]:
    leg = c.get("leg", "left")
    ankle, other = ANKLES[leg], ANKLES["right" if leg == "left" else "left"]
    y = m.j[:, ankle, 1]
    top = int(np.argmax(y))
    near = slice(max(top - int(m.fps), 0), top + int(m.fps) + 1)
    other_top = float(m.j[near, other, 1].max())
    checks = [
        _c(f"{leg}_ankle_height_m", y[top], y[top] >= 0.3, ">= 0.3 m above the floor"),
        _c(
            "other_ankle_height_m",
            other_top,
            other_top <= 0.2,
            "<= 0.2 m within 1 s of the kick (standing on the other foot)",
        ),
    ]
    rel = m.body(ankle)[top]
    if c.get("kick") == "front":
        checks.append(_c("kick_forward_m", rel[2], rel[2] >= 0.3, ">= 0.3 m in front of the pelvis"))
    elif c.get("kick") == "side":
        out = _sign(leg) * rel[0]
        checks.append(
            _c(
                "kick_sideways_m",
                out,
                out >= 0.3 and out >= rel[2],
                f">= 0.3 m to the {leg}, more than forward",
            )
        )
    if "count" in c:
        checks += _count_check("kicks", geo.count_dips(-y, -0.3, -0.15), c)
    return checks


def _kick(m, c):
    fwd, left = m.displacement()
    return _kick_checks(m, c) + [
        _c("displacement_m", np.hypot(fwd, left), np.hypot(fwd, left) <= 0.5, "<= 0.5 m (in place)")
    ]


def _stretch_arms(m, c):
    out_l, out_r = m.body(20, CHEST)[:, 0], -m.body(21, CHEST)[:, 0]
    level = np.maximum(np.abs(m.above(20, 16)), np.abs(m.above(21, 17)))
    wide = (np.minimum(out_l, out_r) >= 0.55) & (level <= 0.2)
    return [
        _c(
            "arms_out_frames",
            wide.sum(),
            wide.sum() >= 8,
            ">= 8 frames with both wrists >= 0.55 m to their sides, within 0.2 m of shoulder height",
        )
    ]


def _push(m, c):
    ahead = np.minimum(m.body(20, CHEST)[:, 2], m.body(21, CHEST)[:, 2])
    high = np.minimum(m.above(20, PELVIS), m.above(21, PELVIS))
    low = np.maximum(m.above(20, HEAD), m.above(21, HEAD))
    apart = np.linalg.norm(m.j[:, 20] - m.j[:, 21], axis=-1)
    both = (ahead >= 0.42) & (high >= 0.1) & (low <= 0.0) & (apart <= 0.65)
    return [
        _c(
            "both_hands_out_frames",
            both.sum(),
            both.sum() >= 5,
            ">= 5 frames with both wrists >= 0.42 m in front of the chest, between pelvis and head",
        )
    ]


def _head_yaw(m: Measures) -> np.ndarray:
    """Head turn (degrees, T) from the neck -> head direction relative to the body, + to the left."""
    d = m.body(15, 12)
    return np.degrees(np.arctan2(d[:, 0], d[:, 2]))


def _look_around(m, c):
    yaw = _head_yaw(m)
    hi, lo = float(yaw.max()), float(yaw.min())
    fwd, left = m.displacement()
    checks = [
        _c("displacement_m", np.hypot(fwd, left), np.hypot(fwd, left) <= 0.4, "<= 0.4 m (in place)"),
        _c("turn_deg", m.turn, abs(m.turn) <= 40.0, "|turn| <= 40 (the body keeps facing the same way)"),
    ]
    look = c.get("look", "both")
    if look in ("both", "left"):
        checks.append(_c("head_left_deg", hi, hi >= 30.0, ">= 30 deg to the left"))
    if look in ("both", "right"):
        checks.append(_c("head_right_deg", -lo, -lo >= 30.0, ">= 30 deg to the right"))
    if look == "left":
        checks.append(_c("head_right_deg", -lo, -lo <= 15.0, "<= 15 deg to the right"))
    if look == "right":
        checks.append(_c("head_left_deg", hi, hi <= 15.0, "<= 15 deg to the left"))
    return checks


ELBOWS = {"left": 18, "right": 19}


def _point(m, c):
    hand = c["hand"]
    wrist, shoulder = HANDS[hand]
    other, other_shoulder = HANDS["right" if hand == "left" else "left"]
    upper = m.j[:, ELBOWS[hand]] - m.j[:, shoulder]
    fore = m.j[:, wrist] - m.j[:, ELBOWS[hand]]
    cos = (upper * fore).sum(-1) / np.maximum(
        np.linalg.norm(upper, axis=-1) * np.linalg.norm(fore, axis=-1), 1e-9
    )
    rel = m.body(wrist, shoulder)
    out = (cos >= np.cos(np.radians(35.0))) & (np.linalg.norm(rel, axis=-1) >= 0.45) & (rel[:, 1] >= -0.25)
    other_up = float(m.above(other, other_shoulder).max())
    checks = [
        _c(
            f"{hand}_arm_out_frames", out.sum(), out.sum() >= 10, ">= 10 frames with the arm straight and out"
        ),
        _c("other_wrist_above_shoulder_m", other_up, other_up <= -0.15, "<= -0.15 (the other arm down)"),
    ]
    if "where" in c and out.any():
        d = np.median(rel[out], axis=0)
        side, ahead = float(d[0]), float(d[2])
        if c["where"] == "ahead":
            checks.append(
                _c("point_forward_m", ahead, ahead >= 0.3 and ahead >= abs(side), "ahead >= |sideways|")
            )
        else:
            s = _sign(c["where"])
            checks.append(
                _c(
                    "point_sideways_m",
                    s * side,
                    s * side >= 0.3 and s * side >= ahead,
                    f"to the {c['where']}",
                )
            )
    return checks


def _carry(m, c):
    moving = np.concatenate([[False], m.speed > 0.3])
    ahead = np.minimum(m.body(20)[:, 2], m.body(21)[:, 2])
    share = float((ahead[moving] >= 0.2).mean()) if moving.any() else 0.0
    return _forward_travel(m, 1.0) + [
        _c("hands_in_front_share", share, share >= 0.8, ">= 0.8 of the walk with both wrists >= 0.2 m ahead")
    ]


# --- terrain ----------------------------------------------------------------------------


def _step_over(m, c):
    lifts = [float(m.j[:, a, 1].max()) for a in (7, 8)]
    rise = m.rise()
    return _forward_travel(m, 0.8) + [
        _c("lower_ankle_peak_m", min(lifts), min(lifts) >= 0.25, ">= 0.25 m (both feet lifted over)"),
        _c("level_change_m", rise, abs(rise) <= 0.08, "|change| <= 0.08 m (the same floor after)"),
    ]


def _vertical(m: Measures, c: dict, lo: float, hi: float) -> list[Check]:
    rise = m.rise()
    if c.get("vertical") == "up":
        return [_c("level_change_m", rise, lo <= rise <= hi, f"+{lo}..+{hi} m (up)")]
    if c.get("vertical") == "down":
        return [_c("level_change_m", rise, -hi <= rise <= -lo, f"-{hi}..-{lo} m (down)")]
    return [_c("level_change_m", abs(rise), lo <= abs(rise) <= hi, f"|change| {lo}..{hi} m")]


def _platform(m, c):
    fwd, _ = m.displacement()
    return _vertical(m, c, 0.1, 0.45) + [_c("forward_m", fwd, fwd >= 0.2, ">= 0.2 m forward")]


def _stairs(m, c):
    fwd, _ = m.displacement()
    return _vertical(m, c, 0.3, 1.5) + [_c("forward_m", fwd, fwd >= 0.6, ">= 0.6 m forward")]


# --- sequences --------------------------------------------------------------------------


def _walk_before(m: Measures, end: int, minimum: float = 1.0) -> Check:
    fwd, _ = m.displacement(0, max(end, 1))
    return _c("walk_before_m", fwd, fwd >= minimum, f">= {minimum} m forward first")


def _walk_then_sit(m, c):
    seated = _seated(m)
    first = int(np.argmax(seated)) if seated.any() else len(seated) - 1
    run = _longest(seated)
    return [
        _walk_before(m, first),
        _c("turn_deg", abs(m.turn), abs(m.turn) >= 120.0, "|turn| >= 120 (turned around)"),
        _c("seated_frames", run, run >= 12, ">= 12 frames seated"),
        _c("seated_at_end", float(seated[-3:].all()), bool(seated[-3:].all()), "seated at the end"),
    ]


def _walk_then_kick(m, c):
    ankle = ANKLES[c.get("leg", "left")]
    top = int(np.argmax(m.j[:, ankle, 1]))
    return [_walk_before(m, top)] + _kick_checks(m, c)


def _walk_then_bow(m, c):
    deepest = int(np.argmax(m.trunk_pitch))
    return [_walk_before(m, deepest)] + _bow(m, c)


def _pick_up_and_carry(m, c):
    low = m.j[:, [20, 21], 1].min(1)
    k = int(np.argmin(low))
    fwd, _ = m.displacement(k, -1)
    moving = np.concatenate([[False], m.speed > 0.3])
    moving[: k + 1] = False
    ahead = np.minimum(m.body(20)[:, 2], m.body(21)[:, 2])
    share = float((ahead[moving] >= 0.2).mean()) if moving.any() else 0.0
    return [
        _c("wrist_min_height_m", low[k], low[k] <= 0.35, "<= 0.35 m (a hand down at the floor)"),
        _c("walk_after_m", fwd, fwd >= 1.0, ">= 1 m forward after picking up"),
        _c("hands_in_front_share", share, share >= 0.8, ">= 0.8 of the walk with both wrists >= 0.2 m ahead"),
    ]


PROBES: dict[str, Callable[[Measures, dict], list[Check]]] = {
    "walk": _walk,
    "jog": _jog,
    "run": _run,
    "walk_backward": _backward,
    "sidestep_left": _sidestep,
    "sidestep_right": _sidestep,
    "crouch_walk": _crouch_walk,
    "stop_and_go": _stop_and_go,
    "walk_to_point": _walk_to_point,
    "turn_left": _turn_in_place,
    "turn_right": _turn_in_place,
    "circle_cw": _circle,
    "circle_ccw": _circle,
    "curve_left": _curve,
    "curve_right": _curve,
    "zigzag": _zigzag,
    "jump_in_place": _jump_in_place,
    "jump_forward": _jump_forward,
    "squat": _squat,
    "kneel": _kneel,
    "wave_left": _wave,
    "wave_right": _wave,
    "raise_arm": _raise_arm,
    "raise_both_arms": _raise_arm,
    "reach_forward": _reach_forward,
    "reach_up": _reach_up,
    "reach_sideways": _reach_sideways,
    "punch": _punch,
    "clap": _clap,
    "walk_and_wave": _walk_and_wave,
    "turn_then_walk": _turn_then_walk,
    "walk_then_squat": _walk_then_squat,
    "sit_down": _sit_down,
    "lie_down": _lie_down,
    "bow": _bow,
    "pick_up": _pick_up,
    "kick": _kick,
    "stretch_arms": _stretch_arms,
    "push": _push,
    "look_around": _look_around,
    "point": _point,
    "carry": _carry,
    "step_over": _step_over,
    "platform": _platform,
    "stairs": _stairs,
    "walk_then_sit": _walk_then_sit,
    "walk_then_kick": _walk_then_kick,
    "walk_then_bow": _walk_then_bow,
    "pick_up_and_carry": _pick_up_and_carry,
}
"""The probe of each motion family, by name."""


def probe(motion: Motion | np.ndarray, family: str, claims: dict[str, Any]) -> ProbeResult:
    """Check a motion against a family and the claims of a caption.

    Args:
        motion: a :class:`~controlmm.motion.Motion` or joints (T, 22, 3) in the HumanML3D frame.
        family: the family name (see :data:`PROBES`).
        claims: what the caption states, e.g. ``{"hand": "left"}`` or ``{"count": 2}``.
    """
    if family not in PROBES:
        raise ControlMMError(f"no probe for family '{family}'; known: {', '.join(PROBES)}")
    if isinstance(motion, Motion):
        joints, fps = motion.joints, float(motion.fps)
    else:
        joints, fps = motion, 20.0
    return ProbeResult(family, tuple(PROBES[family](Measures(joints, fps), dict(claims))))


def check(case: ProbeCase | dict[str, Any], motion: Motion | np.ndarray) -> ProbeResult:
    """Probe ``motion`` for a caption case (a :class:`ProbeCase` or a metadata record with a
    ``family`` and, optionally, ``claims``; a record's claims default to its first caption's)."""
    if isinstance(case, ProbeCase):
        return probe(motion, case.family, case.claims)
    claims = case.get("claims")
    if claims is None:
        claims = case["captions"][0]["claims"] if case.get("captions") else {}
    return probe(motion, case["family"], claims)
