"""Jumps: in place (n times) and forward.

Each jump: a counter-movement crouch with the arms swinging back, a push-off that rolls
both feet onto the toes while the arms swing up, a ballistic flight (the pelvis follows a
parabola under gravity, the feet tuck), a landing on the balls of the feet that the legs
absorb, and recovery (or the next jump).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from controlmm.corpus.curves import keyframes
from controlmm.corpus.families.base import Person, finish, frames_for, standing_plan, times
from controlmm.corpus.family import Family
from controlmm.corpus.feet import Stance, foot_track
from controlmm.corpus.rig import SIDE_SIGN, heading_vectors
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import FORWARD, counted_slot, times_slot

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

G = 9.81
PREP, PUSH, ABSORB, RECOVER = 0.35, 0.15, 0.25, 0.45
PUSH_PITCH, LAND_PITCH = -0.7, -0.45


def _r(x: float) -> float:
    return float(round(float(x), 4))


def _sample(rng, count_choices, forward: bool):
    n = int(rng.choice(count_choices))
    heights = [rng.uniform(0.14, 0.3) for _ in range(n)]
    dists = [rng.uniform(0.5, 1.1) if forward else rng.uniform(-0.03, 0.03) for _ in range(n)]
    gaps = [rng.uniform(0.0, 0.4) for _ in range(n)]
    idle = rng.uniform(0.3, 0.9)
    per_jump = (PREP + PUSH + 2 * np.sqrt(2 * h / G) + ABSORB + g for h, g in zip(heights, gaps, strict=True))
    total = idle + sum(per_jump)
    total += RECOVER + rng.uniform(0.4, 1.0)
    return {
        "count": n,
        "heights": [_r(h) for h in heights],
        "distances": [_r(d) for d in dists],
        "gaps": [_r(g) for g in gaps],
        "idle": _r(idle),
        "seconds": _r(max(min(total, 9.8), 2.2)),
    }


def build_jumps(p: dict, rng: np.random.Generator) -> np.ndarray:
    n_raw = frames_for(p["seconds"])
    t = times(n_raw)
    person = Person.sample(rng)
    fwd, _ = heading_vectors(np.array(person.yaw0))
    fwd2 = fwd[[0, 2]]
    stand = person.stand_height
    h_to = stand + 0.05
    crouch = rng.uniform(0.12, 0.22)

    # Key times and pelvis height / ground progress knots (time, height, vertical speed).
    knots = [(0.0, stand, 0.0)]
    prog = [(0.0, 0.0, 0.0)]
    flights = []
    arm_t, arm_v = [0.0], [0.05]
    lean_t, lean_v = [0.0], [0.0]
    cursor, travelled = p["idle"], 0.0
    for k in range(p["count"]):
        h, d = p["heights"][k], p["distances"][k]
        tf = 2.0 * np.sqrt(2.0 * h / G)
        v0 = np.sqrt(2.0 * G * h)
        vx = d / (tf + 0.5 * (PUSH + ABSORB))
        t_bottom = cursor + PREP
        t_to = t_bottom + PUSH
        t_land = t_to + tf
        if k == 0:
            knots.append((cursor, stand, 0.0))
            prog.append((cursor, travelled, 0.0))
        knots += [(t_bottom, stand - crouch, 0.0), (t_to, h_to, v0)]
        prog += [(t_bottom, travelled, 0.0), (t_to, travelled + 0.5 * vx * PUSH, vx)]
        flights.append((t_to, t_land, h, travelled + 0.5 * vx * PUSH, vx))
        travelled += 0.5 * vx * PUSH + vx * tf
        knots.append((t_land, h_to, -v0))
        prog.append((t_land, travelled, vx))
        travelled += 0.5 * vx * ABSORB
        t_abs = t_land + ABSORB
        prog.append((t_abs, travelled, 0.0))
        arm_t += [cursor, t_bottom, t_to + 0.1, t_land, t_abs]
        arm_v += [0.05, -0.7, 1.3, 0.6, 0.1]
        lean_t += [cursor, t_bottom, t_to, t_land, t_abs]
        lean_v += [0.0, 0.35, -0.05, 0.1, 0.3]
        cursor = t_abs + p["gaps"][k]
        knots.append((t_abs, stand - crouch * rng.uniform(0.5, 0.9), 0.0))
        if p["gaps"][k] > 0.05:
            knots.append((cursor, stand - 0.03, 0.0))
    t_end = cursor + RECOVER
    knots.append((t_end, stand, 0.0))
    prog.append((t_end, travelled, 0.0))
    arm_t.append(t_end)
    arm_v.append(0.05)
    lean_t.append(t_end)
    lean_v.append(0.0)

    height = _hermite(knots, t)
    ground = _hermite(prog, t)
    for t0, t1, h, g0, vx in flights:
        m = (t >= t0) & (t <= t1)
        tau = t[m] - t0
        height[m] = h_to + np.sqrt(2 * G * h) * tau - 0.5 * G * tau**2
        ground[m] = g0 + vx * tau

    # Feet: planted between flights, rolling onto the toes for take-off and landing on them.
    stances = {}
    feet0 = person.initial_feet(np.zeros(2), person.yaw0)
    for side in ("left", "right"):
        base, yaw = feet0[side]
        lst = [Stance(-np.inf, np.inf, base, yaw)]
        for t0, t1, h, _g0, vx in flights:
            lst[-1].t_off = t0
            lst[-1].lift_pitch = PUSH_PITCH
            lst[-1].lift_time = PUSH + 0.05
            land_g = float(np.interp(t1 + ABSORB, t, ground))
            xz = base + fwd2 * (land_g + 0.06 * (vx > 0))
            st = Stance(t1, np.inf, xz, yaw, land_pitch=LAND_PITCH, land_time=0.12, clearance=h + 0.06)
            st.swing_shape = "jump"
            lst.append(st)
        stances[side] = lst

    plan = standing_plan(rng, person, t, stances=stances)
    plan.feet = {s: foot_track(s, stances[s], t) for s in stances}
    plan.root_xz = ground[:, None] * fwd2[None]
    plan.pelvis_height = height
    plan.reach = 0.999
    lean = keyframes(t, lean_t, lean_v)
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.5 * lean
    plan.spine_pitch = plan.get("spine_pitch") + 0.5 * lean
    plan.head_pitch = plan.get("head_pitch") - 0.4 * lean
    arm_flex = keyframes(t, arm_t, arm_v)
    for side in ("left", "right"):
        arm = plan.arms[side]
        arm.flex = arm_flex + 0.05 * SIDE_SIGN[side] * rng.uniform(-1, 1)
        arm.elbow = arm.elbow + 0.3 * np.clip(arm_flex, 0.0, None)
    return finish(plan)


def _hermite(knots: list[tuple[float, float, float]], t: np.ndarray) -> np.ndarray:
    knots = sorted(knots, key=lambda k: k[0])
    ts: list[float] = []
    ys: list[float] = []
    vs: list[float] = []
    for kt, ky, kv in knots:
        if ts and kt <= ts[-1] + 1e-6:
            continue
        ts.append(kt)
        ys.append(ky)
        vs.append(kv)
    spline = CubicHermiteSpline(ts, ys, vs)
    return np.where(t <= ts[-1], spline(np.clip(t, ts[0], ts[-1])), ys[-1])


def _in_place_slots(p):
    return {
        "times": times_slot(p["count"]),
        "jumps": counted_slot(p["count"], "jump", "jumps"),
        "hops": counted_slot(p["count"], "hop", "hops"),
    }


FAMILIES.append(
    Family(
        name="jump_in_place",
        group="jumping",
        sample=lambda rng: _sample(rng, [1, 2, 3, 4], False),
        build=build_jumps,
        templates=(
            Template("{subj} jumps {times}"),
            Template("{subj} jumps in place {times}"),
            Template("{subj} jumps up and down {times}"),
            Template("{subj} does {jumps} on the spot"),
            Template("{subj} makes {jumps} in place"),
            Template("standing still, {subj} hops {times}"),
            Template("{subj} performs {hops} without moving from the spot", held=True),
            Template("{subj} leaps straight up {times}", held=True),
        ),
        slots=_in_place_slots,
        core=lambda p: {"count": p["count"], "in_place": True},
    )
)


def _forward_slots(p):
    return {
        "times": times_slot(p["count"]),
        "jumps": counted_slot(p["count"], "jump", "jumps"),
        "forward": FORWARD,
        "leap": Slot(("jumps",), ("leaps", "bounds")),
    }


FAMILIES.append(
    Family(
        name="jump_forward",
        group="jumping",
        sample=lambda rng: _sample(rng, [1, 1, 2], True),
        build=build_jumps,
        templates=(
            Template("{subj} {leap} {forward} {times}"),
            Template("{subj} does {jumps} {forward}"),
            Template("{subj} {leap} {forward} with both feet {times}"),
            Template("{subj} makes {jumps} {forward}"),
            Template("{subj} does a standing long jump {times}"),
            Template("from a standing position {subj} {leap} {forward} {times}", held=True),
            Template("{subj} hops {forward} on both feet {times}", held=True),
        ),
        slots=_forward_slots,
        core=lambda p: {"count": p["count"], "travel": "forward"},
    )
)
