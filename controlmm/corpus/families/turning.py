"""Changing direction: turn in place, walk in a circle, curve, zigzag."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import keyframes, ramp, window
from controlmm.corpus.families.base import Person, Style, finish, frames_for, locomotion_plan, times
from controlmm.corpus.families.walking import cadence, walk_duty
from controlmm.corpus.family import Family
from controlmm.corpus.gait import Gait, RootPath
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import FORWARD, WALK, side_slot
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

SIGN = {"left": 1.0, "right": -1.0}


def _r(x: float) -> float:
    return float(round(float(x), 4))


# turn in place ----------------------------------------------------------------------------

ANGLE_DEG = {
    90: ("90 degrees", "ninety degrees"),
    180: ("180 degrees",),
    270: ("270 degrees",),
    360: ("360 degrees",),
}
ANGLE_NOUN = {
    90: (("a quarter turn", "a ninety degree turn"), ("a right angle turn",)),
    180: (("a half turn", "a u-turn", "a 180 degree turn"), ("a turnaround",)),
    270: (("a three quarter turn",), ("a 270 degree turn",)),
    360: (("a full turn", "a complete turn", "a full circle"), ("a 360 degree spin",)),
}


def turn_in_place(
    rng: np.random.Generator,
    person: Person,
    t: np.ndarray,
    side: str,
    angle_deg: float,
    start: float,
    duration: float,
    path_xz: np.ndarray | None = None,
):
    """Plan a stepping turn of ``angle_deg`` to ``side`` between ``start`` and ``start + duration``."""
    yaw = person.yaw0 + SIGN[side] * np.radians(angle_deg) * ramp(t, start, start + duration)
    xz = np.zeros((len(t), 2)) if path_xz is None else path_xz
    path = RootPath(t=t, xz=xz, yaw=yaw)
    gait = Gait(
        cadence=2.1,  # steps/s: stepping round on the spot, a little faster than walking
        duty=0.55,
        width=person.width,
        step_ref=0.3,
        toe_out=person.toe_out,
        first=side,
        start=max(start - 0.15, 0.0),
        clearance=0.05,
        ref_frac=0.5,
        min_turn=0.1,
    )
    return path, gait


def _turn_sample(rng):
    angle = int(rng.choice([90, 180, 360], p=[0.45, 0.4, 0.15]))
    rate = rng.uniform(70.0, 110.0)
    duration = angle / rate
    idle = rng.uniform(0.2, 1.2)
    seconds = max(idle + duration + rng.uniform(1.0, 1.6), 2.2)
    return {
        "angle": angle,
        "rate": _r(rate),
        "duration": _r(duration),
        "idle": _r(idle),
        "seconds": _r(seconds),
    }


def _turn_builder(side: str):
    def build(p, rng):
        n = frames_for(p["seconds"])
        t = times(n)
        person = Person.sample(rng)
        path, gait = turn_in_place(rng, person, t, side, p["angle"], p["idle"], p["duration"])
        plan = locomotion_plan(
            rng, person, t, path, gait, Style(kind="walk", bob=0.01, drop=0.01, lean=0.0, arm_swing=0.3)
        )
        return finish(plan)

    return build


def _turn_slots(p, side):
    deg, (noun, noun_held) = ANGLE_DEG[p["angle"]], ANGLE_NOUN[p["angle"]]
    return {
        "dir": side_slot(side),
        "deg": Slot(deg, (), ("angle", p["angle"])),
        "noun": Slot(noun, noun_held, ("angle", p["angle"])),
    }


def _turn_family(side: str) -> Family:
    return Family(
        name=f"turn_{side}",
        group="turning",
        sample=_turn_sample,
        build=_turn_builder(side),
        templates=(
            Template("{subj} turns {dir}"),
            Template("{subj} turns {deg} {dir}"),
            Template("{subj} makes {noun} {dir}"),
            Template("{subj} turns {dir} in place"),
            Template("standing in place, {subj} turns {deg} {dir}"),
            Template("{subj} does {noun} {dir} on the spot"),
            Template("{subj} pivots {deg} {dir}", held=True),
            Template("{subj} rotates {poss} body {dir} by {deg}", held=True),
        ),
        slots=lambda p: _turn_slots(p, side),
        core=lambda p: {"direction": side, "in_place": True},
    )


for _side in ("left", "right"):
    FAMILIES.append(_turn_family(_side))


# circle -----------------------------------------------------------------------------------


def _circle_sample(rng):
    for _ in range(100):
        radius = rng.uniform(0.8, 2.0)
        v = rng.uniform(0.8, 1.3)
        laps = rng.uniform(1.05, 1.2)
        idle, ease = rng.uniform(0.0, 0.5), rng.uniform(0.5, 0.8)
        cruise = (2 * np.pi * radius * laps) / v - ease
        seconds = idle + cruise + 2 * ease + rng.uniform(0.8, 1.2)
        if seconds <= 9.7:
            return {
                "radius": _r(radius),
                "speed": _r(v),
                "laps": _r(laps),
                "idle": _r(idle),
                "ease": _r(ease),
                "cruise": _r(cruise),
                "seconds": _r(seconds),
                "first": str(rng.choice(["left", "right"])),
            }
    raise RuntimeError("no circle fits in 9.8 s")


def _circle_builder(rotation: str):
    sign = 1.0 if rotation == "counterclockwise" else -1.0

    def build(p, rng):
        n = frames_for(p["seconds"])
        t = times(n)
        person = Person.sample(rng)
        a, e = p["idle"], p["ease"]
        speed = p["speed"] * window(t, a, a + p["cruise"] + 2 * e, e)
        turn_rate = sign * speed / p["radius"]
        yaw = person.yaw0 + np.concatenate([[0.0], np.cumsum(0.5 * (turn_rate[1:] + turn_rate[:-1]) / FPS)])
        path = RootPath.from_velocity(t, speed, 0.0, yaw, FPS)
        v = p["speed"]
        cad = cadence("walk", v)
        gait = Gait(
            cadence=cad,
            duty=walk_duty(v),
            width=person.width,
            step_ref=v / cad,
            toe_out=person.toe_out,
            first=p["first"],
            start=max(a - 0.05, 0.0),
        )
        plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
        return finish(plan)

    return build


ROTATION = {
    "clockwise": Slot(
        ("clockwise", "in a clockwise direction"),
        ("in the same direction as a clock",),
        ("rotation", "clockwise"),
    ),
    "counterclockwise": Slot(
        ("counterclockwise", "counter-clockwise", "anticlockwise"),
        ("against the clock", "in an anticlockwise direction"),
        ("rotation", "counterclockwise"),
    ),
}
TURN_SIDE = {"clockwise": "right", "counterclockwise": "left"}


def _circle_family(rot: str) -> Family:
    return Family(
        name="circle_cw" if rot == "clockwise" else "circle_ccw",
        group="turning",
        sample=_circle_sample,
        build=_circle_builder(rot),
        templates=(
            Template("{subj} {walk} in a circle {rot}"),
            Template("{subj} {walk} {rot} in a circle"),
            Template("{subj} walks around in a full circle {rot}"),
            Template("{subj} {walk} in a circle, turning {side}"),
            Template("{subj} circles {rot}"),
            Template("{subj} makes a complete loop {rot}", held=True),
            Template("{subj} {walk} in a round path, always turning {side}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "rot": ROTATION[rot], "side": side_slot(TURN_SIDE[rot])},
        core=lambda p: {"rotation": rot},
    )


for _rot in ("clockwise", "counterclockwise"):
    FAMILIES.append(_circle_family(_rot))


# curve ------------------------------------------------------------------------------------


def _curve_sample(rng):
    v = rng.uniform(0.9, 1.5)
    angle = rng.uniform(60.0, 150.0)
    walk = rng.uniform(4.0, 8.5)
    idle = rng.uniform(0.0, 0.5)
    return {
        "speed": _r(v),
        "angle": _r(angle),
        "walk": _r(walk),
        "idle": _r(idle),
        "curve_start": _r(rng.uniform(0.15, 0.35)),
        "curve_len": _r(rng.uniform(0.3, 0.5)),
        "seconds": _r(min(idle + walk + rng.uniform(0.0, 1.0), 9.8)),
        "first": str(rng.choice(["left", "right"])),
        "stops": bool(rng.random() < 0.5),
    }


def _curve_builder(side: str):
    def build(p, rng):
        n = frames_for(p["seconds"])
        t = times(n)
        person = Person.sample(rng)
        a = p["idle"]
        end = a + p["walk"] if p["stops"] else t[-1] + 5.0
        speed = p["speed"] * window(t, a, end, 0.7)
        c0 = a + p["curve_start"] * p["walk"]
        c1 = c0 + p["curve_len"] * p["walk"]
        yaw = person.yaw0 + SIGN[side] * np.radians(p["angle"]) * ramp(t, c0, c1)
        path = RootPath.from_velocity(t, speed, 0.0, yaw, FPS)
        v = p["speed"]
        cad = cadence("walk", v)
        gait = Gait(
            cadence=cad,
            duty=walk_duty(v),
            width=person.width,
            step_ref=v / cad,
            toe_out=person.toe_out,
            first=p["first"],
            start=max(a - 0.05, 0.0),
        )
        plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
        return finish(plan)

    return build


def _curve_family(side: str) -> Family:
    return Family(
        name=f"curve_{side}",
        group="turning",
        sample=_curve_sample,
        build=_curve_builder(side),
        templates=(
            Template("{subj} {walk} {forward} and curves {dir}"),
            Template("{subj} {walk} along a curve {dir}"),
            Template("{subj} {walk} in an arc {dir}"),
            Template("{subj} {walk} {forward}, gradually bending {dir}"),
            Template("{subj} follows a curved path {dir}"),
            Template("{subj} veers {dir} while walking", held=True),
            Template("walking {forward}, {subj} drifts {dir} in a wide arc", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, "dir": side_slot(side)},
        core=lambda p: {"direction": side},
    )


for _side in ("left", "right"):
    FAMILIES.append(_curve_family(_side))


# zigzag -----------------------------------------------------------------------------------


def _zigzag_sample(rng):
    legs = int(rng.choice([3, 4, 5]))
    leg_time = rng.uniform(1.3, 1.9)
    idle = rng.uniform(0.0, 0.4)
    while idle + legs * leg_time + 1.0 > 9.6:
        legs -= 1
    return {
        "legs": legs,
        "leg_time": _r(leg_time),
        "angle": _r(rng.uniform(30.0, 50.0)),
        "speed": _r(rng.uniform(0.9, 1.4)),
        "idle": _r(idle),
        "first_side": str(rng.choice(["left", "right"])),
        "seconds": _r(idle + legs * leg_time + rng.uniform(0.7, 1.2)),
        "first": str(rng.choice(["left", "right"])),
    }


def _zigzag_build(p, rng):
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    a = p["idle"]
    end = a + p["legs"] * p["leg_time"]
    speed = p["speed"] * window(t, a, end, 0.6)
    phi = np.radians(p["angle"]) * SIGN[p["first_side"]]
    keys_t, keys_v = [a], [phi]
    for k in range(1, p["legs"]):
        mid = a + k * p["leg_time"]
        keys_t += [mid - 0.5, mid + 0.5]
        keys_v += [keys_v[-1], -keys_v[-1]]
    yaw = person.yaw0 + keyframes(t, keys_t, keys_v)
    # Start facing straight ahead, turning into the first leg as walking begins.
    yaw = yaw - phi * (1.0 - ramp(t, a - 0.2, a + 0.5))
    path = RootPath.from_velocity(t, speed, 0.0, yaw, FPS)
    v = p["speed"]
    cad = cadence("walk", v)
    gait = Gait(
        cadence=cad,
        duty=walk_duty(v),
        width=person.width,
        step_ref=v / cad,
        toe_out=person.toe_out,
        first=p["first"],
        start=max(a - 0.05, 0.0),
    )
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
    return finish(plan)


FAMILIES.append(
    Family(
        name="zigzag",
        group="turning",
        sample=_zigzag_sample,
        build=_zigzag_build,
        templates=(
            Template("{subj} {walk} {forward} in a zigzag"),
            Template("{subj} {walk} in a zigzag pattern"),
            Template("{subj} zigzags {forward}"),
            Template("{subj} {walk} {forward}, weaving left and right"),
            Template("{subj} moves in a zig zag line"),
            Template("{subj} {walk} {forward} changing direction from side to side", held=True),
            Template("{subj} takes a zigzagging route {forward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD},
        core=lambda p: {"zigzag": True},
    )
)
