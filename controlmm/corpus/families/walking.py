"""Travelling families: walk, jog, run, walk backwards, sidestep, crouch-walk, stop and go,
walk to a point."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import gentle_noise, keyframes, ramp, window
from controlmm.corpus.families.base import Person, Style, finish, frames_for, locomotion_plan, times
from controlmm.corpus.family import Family
from controlmm.corpus.gait import Gait, RootPath
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import BACKWARD, FORWARD, JOG, RUN, WALK, side_slot, speed_slot
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

SPEEDS = {"slow": (0.6, 0.9), "normal": (1.1, 1.4), "fast": (1.55, 1.8)}


def _r(x: float) -> float:
    return float(round(float(x), 4))


WALK_RATIO = 0.385
"""Step length / step rate of adult walking (m per step/s): about 0.0064 m per step/min, nearly
constant over walking speeds (the "walk ratio", Sekiya & Nagasaki 1998), so the step rate grows
as the square root of the speed: 1.61 steps/s (97 steps/min, 0.62 m steps) at 1.0 m/s, 1.89 (113)
at 1.37 m/s, the self-selected speed of Perry & Burnfield's normal adults."""


def cadence(kind: str, v: float) -> float:
    """Steps per second for a gait at speed ``v`` (m/s)."""
    if kind == "run":
        return 2.75 + 0.08 * v
    if kind == "jog":
        return 2.45 + 0.1 * v
    return float(np.clip(np.sqrt(max(v, 0.05) / WALK_RATIO), 1.2, 2.3))


def walk_duty(v: float) -> float:
    """Stance share of a walking gait cycle at ``v`` m/s: about 62 % at 1 m/s, 60 % at 1.37 m/s
    (Perry & Burnfield's 60/40 stance/swing split), a little more at slow speeds."""
    return float(np.clip(0.66 - 0.045 * v, 0.56, 0.66))


def travel(
    rng: np.random.Generator,
    p: dict,
    kind: str,
    move_dir: float,
    style: Style,
    *,
    duty: float,
    curve: float = 0.04,
    width: float | None = None,
    clearance: float = 0.075,
    ref_frac: float = 0.4,
    speed: np.ndarray | None = None,
    cad: float | None = None,
) -> np.ndarray:
    """Shared builder: a ramped speed along ``move_dir`` (rad from the heading)."""
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    v = p["speed"]
    if speed is None:
        t_stop = t[-1] - p["tail"] if p["stops"] else t[-1] + 5.0
        speed = v * window(t, p["idle"], t_stop, p["ease"], p["ease"])
    yaw = person.yaw0 + gentle_noise(rng, t, curve, (0.05, 0.2)) * (speed / max(v, 1e-6))
    path = RootPath.from_velocity(t, speed, move_dir, yaw, FPS)
    cad = cadence(kind, v) if cad is None else cad
    gait = Gait(
        cadence=cad,
        duty=duty,
        width=person.width if width is None else width,
        step_ref=max(v / cad, 0.2),
        toe_out=person.toe_out,
        first=p["first"],
        start=max(p["idle"] - 0.05, 0.0),
        clearance=clearance,
        ref_frac=ref_frac,
        strike="fore" if kind in ("jog", "run") else "heel",
    )
    plan = locomotion_plan(rng, person, t, path, gait, style)
    if kind == "crouch":
        plan.knee_out = 0.3
        for arm in plan.arms.values():
            arm.flex = arm.flex + 0.35 * plan.extras["activity"]
    return finish(plan)


def _sample_travel(
    rng: np.random.Generator, v: float, cruise: tuple[float, float], stops: float = 0.6
) -> dict:
    """Timing of a travel clip: idle, ease in, ``cruise`` seconds at speed ``v``, then either
    ease out and stand (``stops`` probability) or end while still moving; <= 9.8 s."""
    idle, ease, tail = rng.uniform(0.0, 0.7), rng.uniform(0.5, 1.0), rng.uniform(0.9, 1.4)
    stop = bool(rng.random() < stops)
    fixed = idle + ease + (ease + tail if stop else 0.0)
    run = min(rng.uniform(*cruise), 9.7 - fixed)
    return {
        "speed": _r(v),
        "seconds": _r(fixed + run),
        "idle": _r(idle),
        "ease": _r(ease),
        "tail": _r(tail),
        "stops": stop,
        "first": str(rng.choice(["left", "right"])),
    }


# walk -------------------------------------------------------------------------------------


def _walk_sample(rng):
    cls = str(rng.choice(list(SPEEDS), p=[0.3, 0.4, 0.3]))
    p = _sample_travel(rng, rng.uniform(*SPEEDS[cls]), (1.8, 7.5))
    p["speed_class"] = cls
    return p


def _walk_build(p, rng):
    v = p["speed"]
    style = Style(kind="walk", bob=0.02 + 0.012 * v, drop=0.01, lean=0.02 + 0.03 * v)
    return travel(rng, p, "walk", 0.0, style, duty=walk_duty(v))


FAMILIES.append(
    Family(
        name="walk",
        group="walking",
        sample=_walk_sample,
        build=_walk_build,
        templates=(
            Template("{subj} {walk} {forward} {speed}"),
            Template("{subj} {walk} {speed} {forward}"),
            Template("{subj} takes a few steps {forward} {speed}"),
            Template("{subj} {walk} {forward} {speed} in a straight line"),
            Template("walking {forward} {speed}, {subj} covers some ground", held=True),
            Template("{subj} goes for a walk {forward} {speed}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, "speed": speed_slot(p["speed_class"])},
        core=lambda p: {"travel": "forward"},
    )
)


# jog and run ------------------------------------------------------------------------------


def _jog_sample(rng):
    return _sample_travel(rng, rng.uniform(2.0, 2.7), (1.4, 6.0))


def _jog_build(p, rng):
    style = Style(kind="jog", bob=0.035, drop=0.02, lean=0.1, arm_swing=1.2, elbow=1.0)
    return travel(rng, p, "jog", 0.0, style, duty=0.42, clearance=0.1 * p["speed"], ref_frac=0.4)


FAMILIES.append(
    Family(
        name="jog",
        group="walking",
        sample=_jog_sample,
        build=_jog_build,
        templates=(
            Template("{subj} {jog} {forward}"),
            Template("{subj} {jog} {forward} at a steady pace"),
            Template("{subj} starts to jog {forward}"),
            Template("{subj} is out jogging, moving {forward}"),
            Template("{subj} {jog} {forward} at an easy pace", held=True),
        ),
        slots=lambda p: {"jog": JOG, "forward": FORWARD},
        core=lambda p: {"travel": "forward"},
    )
)


def _run_sample(rng):
    return _sample_travel(rng, rng.uniform(3.1, 4.0), (1.2, 4.5))


def _run_build(p, rng):
    style = Style(kind="run", bob=0.05, drop=0.02, lean=0.2, arm_swing=1.6, elbow=1.3)
    return travel(rng, p, "run", 0.0, style, duty=0.34, clearance=0.1 * p["speed"], ref_frac=0.4)


FAMILIES.append(
    Family(
        name="run",
        group="walking",
        sample=_run_sample,
        build=_run_build,
        templates=(
            Template("{subj} {run} {forward}"),
            Template("{subj} {run} {forward} quickly"),
            Template("{subj} breaks into a run {forward}"),
            Template("{subj} {run} {forward} as fast as possible"),
            Template("at full speed {subj} {run} {forward}", held=True),
        ),
        slots=lambda p: {"run": RUN, "forward": FORWARD},
        core=lambda p: {"travel": "forward"},
    )
)


# walk backwards ---------------------------------------------------------------------------


def _back_sample(rng):
    return _sample_travel(rng, rng.uniform(0.5, 1.0), (1.8, 7.0))


def _back_build(p, rng):
    style = Style(kind="walk", bob=0.02, drop=0.02, lean=0.03, arm_swing=0.6)
    return travel(rng, p, "walk", np.pi, style, duty=0.65, clearance=0.06, ref_frac=0.5)


FAMILIES.append(
    Family(
        name="walk_backward",
        group="walking",
        sample=_back_sample,
        build=_back_build,
        templates=(
            Template("{subj} {walk} {backward}"),
            Template("{subj} {walk} {backward} carefully"),
            Template("{subj} takes several steps {backward}"),
            Template("{subj} backs up, walking {backward}"),
            Template("facing forward, {subj} {walk} {backward}", held=True),
            Template("{subj} retreats by stepping {backward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "backward": BACKWARD},
        core=lambda p: {"travel": "backward"},
    )
)


# sidestep ---------------------------------------------------------------------------------


def _side_sample(rng):
    return _sample_travel(rng, rng.uniform(0.35, 0.6), (1.8, 6.0), stops=1.0)


def _side_builder(side: str):
    def build(p, rng):
        v = p["speed"]
        cad = 1.9 + 0.5 * v
        style = Style(kind="walk", bob=0.012, drop=0.02, lean=0.02, arm_swing=0.3)
        # The feet alternate between open (width + v/cad) and closed (width - v/cad) stances.
        width = max(0.2, v / cad + 0.14)
        p_ = dict(p, first=side)
        return travel(
            rng,
            p_,
            "walk",
            (np.pi / 2) * (1 if side == "left" else -1),
            style,
            duty=0.7,
            width=width,
            clearance=0.05,
            ref_frac=0.3,
            curve=0.02,
            cad=cad,
        )

    return build


def _sidestep_family(side: str) -> Family:
    return Family(
        name=f"sidestep_{side}",
        group="walking",
        sample=_side_sample,
        build=_side_builder(side),
        templates=(
            Template("{subj} sidesteps {dir}"),
            Template("{subj} steps sideways {dir}"),
            Template("{subj} shuffles sideways {dir}"),
            Template("{subj} {walk} sideways {dir}"),
            Template("{subj} moves {dir} with side steps"),
            Template("{subj} slides {dir} with small side steps", held=True),
            Template("with a few side steps {subj} moves {dir}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "dir": side_slot(side)},
        core=lambda p: {"direction": side},
    )


for _side in ("left", "right"):
    FAMILIES.append(_sidestep_family(_side))


# crouch-walk ------------------------------------------------------------------------------


def _crouch_sample(rng):
    return _sample_travel(rng, rng.uniform(0.4, 0.8), (2.0, 7.0))


def _crouch_build(p, rng):
    style = Style(
        kind="crouch",
        bob=0.012,
        drop=rng.uniform(0.2, 0.3),
        lean=rng.uniform(0.5, 0.8),
        arm_swing=0.5,
        elbow=0.5,
    )
    return travel(rng, p, "crouch", 0.0, style, duty=0.68, clearance=0.06, ref_frac=0.45)


FAMILIES.append(
    Family(
        name="crouch_walk",
        group="walking",
        sample=_crouch_sample,
        build=_crouch_build,
        templates=(
            Template("{subj} {walk} {forward} while crouching"),
            Template("{subj} crouches down and walks {forward}"),
            Template("{subj} sneaks {forward} in a crouch"),
            Template("{subj} walks {forward} bent over, staying low"),
            Template("keeping low, {subj} creeps {forward}", held=True),
            Template("{subj} {walk} {forward} in a squatting position", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD},
        core=lambda p: {"travel": "forward", "crouched": True},
    )
)


# stop and go ------------------------------------------------------------------------------


def _stopgo_sample(rng):
    v = rng.uniform(0.9, 1.4)
    walk1, pause, walk2 = rng.uniform(1.6, 2.6), rng.uniform(0.9, 1.8), rng.uniform(1.6, 2.6)
    idle, ease = rng.uniform(0.0, 0.5), rng.uniform(0.5, 0.8)
    seconds = idle + walk1 + pause + walk2 + rng.uniform(0.3, 1.0)
    return {
        "speed": _r(v),
        "seconds": _r(min(seconds, 9.7)),
        "idle": _r(idle),
        "ease": _r(ease),
        "walk1": _r(walk1),
        "pause": _r(pause),
        "tail": 0.0,
        "stops": False,
        "first": str(rng.choice(["left", "right"])),
    }


def _stopgo_build(p, rng):
    n = frames_for(p["seconds"])
    t = times(n)
    a = p["idle"]
    b = a + p["walk1"]
    c = b + p["pause"]
    speed = p["speed"] * (window(t, a, b, p["ease"]) + window(t, c, t[-1] + 5.0, p["ease"]))
    style = Style(kind="walk", bob=0.03, drop=0.01, lean=0.05)
    return travel(rng, p, "walk", 0.0, style, duty=walk_duty(p["speed"]), speed=speed)


FAMILIES.append(
    Family(
        name="stop_and_go",
        group="walking",
        sample=_stopgo_sample,
        build=_stopgo_build,
        templates=(
            Template("{subj} {walk} {forward}, stops for a moment, then keeps walking"),
            Template("{subj} {walk} {forward}, pauses, and continues walking"),
            Template("{subj} walks, comes to a stop, and then walks on"),
            Template("{subj} {walk} {forward} and briefly stops before walking again"),
            Template("{subj} halts in the middle of the walk and then resumes walking {forward}", held=True),
            Template("after a short pause in the walk, {subj} carries on {forward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD},
        core=lambda p: {"travel": "forward", "stops": 1},
    )
)


# walk to a point --------------------------------------------------------------------------


def _point_sample(rng):
    where = str(rng.choice(["ahead", "left", "right"]))
    meters = int(rng.choice([2, 3, 4]))
    dist = meters + rng.uniform(-0.25, 0.25)
    bearing = {"ahead": rng.uniform(-6, 6), "left": rng.uniform(25, 60), "right": -rng.uniform(25, 60)}[where]
    v = rng.uniform(0.9, 1.3)
    walk_time = dist / v + 1.4
    return {
        "where": where,
        "meters": meters,
        "distance": _r(dist),
        "bearing": _r(bearing),
        "speed": _r(v),
        "idle": _r(rng.uniform(0.0, 0.6)),
        "walk_time": _r(walk_time),
        "seconds": _r(min(rng.uniform(0.0, 0.6) + walk_time + rng.uniform(1.0, 1.8), 9.8)),
        "first": str(rng.choice(["left", "right"])),
        "tail": 0.0,
        "stops": True,
    }


def _point_build(p, rng):
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    beta = np.radians(p["bearing"])
    a = p["idle"]
    b = a + p["walk_time"]
    progress = keyframes(t, [a, b], [0.0, 1.0])
    target = p["distance"] * np.array([np.sin(person.yaw0 + beta), np.cos(person.yaw0 + beta)])
    xz = progress[:, None] * target[None]
    yaw = person.yaw0 + beta * ramp(t, a - 0.2, a + 0.8)
    path = RootPath(t=t, xz=xz, yaw=yaw)
    v = p["speed"]
    cad = cadence("walk", v)
    gait = Gait(
        cadence=cad,
        duty=walk_duty(v),
        width=person.width,
        step_ref=v / cad,
        toe_out=person.toe_out,
        first=p["first"],
        start=max(a - 0.2, 0.0),
    )
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.05))
    return finish(plan)


def _where_slot(p):
    w = p["where"]
    if w == "ahead":
        return Slot(
            ("straight ahead", "in front of {poss}", "directly ahead"),
            ("right in front",),
            ("where", "ahead"),
        )
    return Slot(
        (f"ahead and to the {w}", f"diagonally to the front {w}", f"to the front {w}"),
        (f"forward on the {w} side",),
        ("where", w),
    )


def _dist_slot(p):
    m = {2: "two", 3: "three", 4: "four"}[p["meters"]]
    return Slot(
        (f"about {m} meters away", f"roughly {m} meters away", f"{m} meters away"),
        (f"some {p['meters']} meters away", f"around {p['meters']} m away"),
        ("meters", p["meters"]),
    )


FAMILIES.append(
    Family(
        name="walk_to_point",
        group="walking",
        sample=_point_sample,
        build=_point_build,
        templates=(
            Template("{subj} {walk} to a spot {dist} {where} and stops"),
            Template("{subj} {walk} to a point {where}, {dist}, and stops there"),
            Template("{subj} heads to a place {where} {dist} and stands still"),
            Template("{subj} {walk} {where} to a spot {dist} and stops"),
            Template("{subj} makes {poss} way to a mark {dist} {where} and halts", held=True),
            Template("{subj} approaches a location {where}, {dist}, then stops", held=True),
        ),
        slots=lambda p: {"walk": WALK, "where": _where_slot(p), "dist": _dist_slot(p)},
        core=lambda p: {"stops_at_end": True},
    )
)
