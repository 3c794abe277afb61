"""Compositions: walk while waving, turn then walk, walk then squat."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import ramp, window
from controlmm.corpus.families.base import Person, Style, finish, frames_for, locomotion_plan, times
from controlmm.corpus.families.gestures import add_wave
from controlmm.corpus.families.lowering import apply_squats
from controlmm.corpus.families.turning import ANGLE_DEG, ANGLE_NOUN, SIGN
from controlmm.corpus.families.walking import cadence, walk_duty
from controlmm.corpus.family import Family
from controlmm.corpus.gait import Gait, RootPath
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import FORWARD, WALK, counted_slot, hand_slot, side_slot, times_slot
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


def _walk_gait(person: Person, v: float, first: str, start: float) -> Gait:
    cad = cadence("walk", v)
    return Gait(
        cadence=cad,
        duty=walk_duty(v),
        width=person.width,
        step_ref=v / cad,
        toe_out=person.toe_out,
        first=first,
        start=max(start, 0.0),
    )


# walk while waving ------------------------------------------------------------------------


def _walkwave_sample(rng):
    v = rng.uniform(0.9, 1.4)
    idle = rng.uniform(0.0, 0.5)
    freq = rng.uniform(1.4, 2.4)
    cycles = int(rng.integers(4, 8))
    wave_start = idle + rng.uniform(0.5, 1.2)
    seconds = wave_start + 0.6 + cycles / freq + 0.8 + rng.uniform(0.3, 1.2)
    return {
        "speed": _r(v),
        "idle": _r(idle),
        "hand": str(rng.choice(["left", "right"])),
        "wave": {
            "idle": _r(wave_start),
            "rise": 0.6,
            "fall": 0.7,
            "action": _r(cycles / freq),
            "freq": _r(freq),
            "cycles": cycles,
            "amplitude": _r(rng.uniform(0.08, 0.14)),
            "height": _r(rng.uniform(0.36, 0.46)),
        },
        "seconds": _r(min(seconds, 9.8)),
        "first": str(rng.choice(["left", "right"])),
    }


def _walkwave_build(p, rng):
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    speed = p["speed"] * window(t, p["idle"], t[-1] + 5.0, 0.7)
    path = RootPath.from_velocity(t, speed, 0.0, np.full(len(t), person.yaw0), FPS)
    plan = locomotion_plan(
        rng,
        person,
        t,
        path,
        _walk_gait(person, p["speed"], p["first"], p["idle"] - 0.05),
        Style(kind="walk", bob=0.03, lean=0.04),
    )
    add_wave(plan, p["wave"], p["hand"], t)
    return finish(plan)


FAMILIES.append(
    Family(
        name="walk_and_wave",
        group="combos",
        sample=_walkwave_sample,
        build=_walkwave_build,
        templates=(
            Template("{subj} {walk} {forward} while waving {poss} {hand}"),
            Template("{subj} is walking {forward} and waving {poss} {hand}"),
            Template("{subj} {walk} {forward} and waves with {poss} {hand}"),
            Template("while walking {forward}, {subj} waves {poss} {hand}"),
            Template("{subj} raises {poss} {hand} and waves while walking"),
            Template("{subj} greets someone with {poss} {hand} without stopping {poss} walk", held=True),
            Template("waving {poss} {hand} overhead, {subj} strolls {forward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, "hand": hand_slot(p["hand"])},
        core=lambda p: {"hand": p["hand"], "travel": "forward"},
    )
)


# turn then walk ---------------------------------------------------------------------------


def _turnwalk_sample(rng):
    angle = int(rng.choice([90, 180]))
    duration = angle / rng.uniform(70.0, 110.0)
    idle = rng.uniform(0.2, 0.8)
    walk = rng.uniform(2.5, 4.5)
    return {
        "side": str(rng.choice(["left", "right"])),
        "angle": angle,
        "duration": _r(duration),
        "idle": _r(idle),
        "speed": _r(rng.uniform(0.9, 1.4)),
        "walk": _r(walk),
        "seconds": _r(min(idle + duration + 0.3 + walk, 9.8)),
    }


def _turnwalk_build(p, rng):
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    a = p["idle"]
    b = a + p["duration"]
    yaw = person.yaw0 + SIGN[p["side"]] * np.radians(p["angle"]) * ramp(t, a, b)
    speed = p["speed"] * window(t, b - 0.1, t[-1] + 5.0, 0.7)
    path = RootPath.from_velocity(t, speed, 0.0, yaw, FPS)
    cad = cadence("walk", p["speed"])
    gait = Gait(
        cadence=np.where(t < b, 2.1, cad),
        duty=0.6,
        width=person.width,
        step_ref=p["speed"] / cad,
        toe_out=person.toe_out,
        first=p["side"],
        start=max(a - 0.15, 0.0),
        ref_frac=0.45,
    )
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
    return finish(plan)


def _turnwalk_slots(p):
    deg, (noun, noun_held) = ANGLE_DEG[p["angle"]], ANGLE_NOUN[p["angle"]]
    return {
        "walk": WALK,
        "forward": FORWARD,
        "dir": side_slot(p["side"]),
        "deg": Slot(deg, (), ("angle", p["angle"])),
        "noun": Slot(noun, noun_held, ("angle", p["angle"])),
    }


FAMILIES.append(
    Family(
        name="turn_then_walk",
        group="combos",
        sample=_turnwalk_sample,
        build=_turnwalk_build,
        templates=(
            Template("{subj} turns {dir} and then {walk} {forward}"),
            Template("{subj} turns {deg} {dir} and walks away"),
            Template("{subj} makes {noun} {dir}, then walks {forward}"),
            Template("{subj} turns {dir} before walking {forward}"),
            Template("after turning {dir}, {subj} {walk} {forward}"),
            Template("{subj} spins {dir} by {deg} and sets off walking", held=True),
            Template("{subj} faces {dir} with {noun} and begins to walk", held=True),
        ),
        slots=_turnwalk_slots,
        core=lambda p: {"direction": p["side"]},
    )
)


# walk then squat --------------------------------------------------------------------------


def _walksquat_sample(rng):
    v = rng.uniform(0.9, 1.3)
    idle = rng.uniform(0.0, 0.5)
    walk = rng.uniform(2.0, 3.6)
    count = int(rng.choice([1, 2], p=[0.7, 0.3]))
    squat = {
        "count": count,
        "depth": _r(rng.uniform(0.3, 0.45)),
        "down": _r(rng.uniform(0.6, 1.0)),
        "hold": _r(rng.uniform(0.1, 0.5)),
        "up": _r(rng.uniform(0.5, 0.8)),
        "rest": _r(rng.uniform(0.15, 0.4)),
        "arms": str(rng.choice(["forward", "low"])),
    }
    squat_time = count * (squat["down"] + squat["hold"] + squat["up"]) + (count - 1) * squat["rest"]
    seconds = idle + walk + 0.9 + squat_time + rng.uniform(0.3, 0.8)
    return {
        "speed": _r(v),
        "idle": _r(idle),
        "walk": _r(walk),
        "squat": squat,
        "count": count,
        "seconds": _r(min(seconds, 9.8)),
        "first": str(rng.choice(["left", "right"])),
    }


def _walksquat_build(p, rng):
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    a = p["idle"]
    b = a + p["walk"]
    speed = p["speed"] * window(t, a, b, 0.7)
    path = RootPath.from_velocity(t, speed, 0.0, np.full(len(t), person.yaw0), FPS)
    plan = locomotion_plan(
        rng,
        person,
        t,
        path,
        _walk_gait(person, p["speed"], p["first"], a - 0.05),
        Style(kind="walk", bob=0.03, lean=0.04),
    )
    apply_squats(plan, p["squat"], t, b + 0.9, person)
    return finish(plan)


FAMILIES.append(
    Family(
        name="walk_then_squat",
        group="combos",
        sample=_walksquat_sample,
        build=_walksquat_build,
        templates=(
            Template("{subj} {walk} {forward}, stops and squats down {times}"),
            Template("{subj} {walk} {forward} and then squats {times}"),
            Template("{subj} walks a few steps, then does {squats}"),
            Template("after walking {forward}, {subj} squats {times}"),
            Template("{subj} {walk} {forward} before crouching into a squat {times}"),
            Template("{subj} comes to a halt after a short walk and squats {times}", held=True),
            Template("{subj} strolls {forward}, halts, and bends down into {squats}", held=True),
        ),
        slots=lambda p: {
            "walk": WALK,
            "forward": FORWARD,
            "times": times_slot(p["count"]),
            "squats": counted_slot(p["count"], "squat", "squats"),
        },
        core=lambda p: {"travel": "forward", "count": p["count"]},
    )
)
