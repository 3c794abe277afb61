"""Walking over objects: step over a low obstacle, step up onto / down from a platform, walk up
or down stairs.

The footholds are planned explicitly along the walking line (one foot per stair tread, the
obstacle between two footholds, the platform edge between the feet) with the gait's heel-toe
roll; swings are lifted until toes and heels clear the objects
(:func:`~controlmm.corpus.feet.foot_track` with a terrain). The pelvis rises and sinks with
the surface under the feet. The objects are boxes returned with the joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.corpus.curves import smoothstep
from controlmm.corpus.families.base import Person, Style, axes, finish, frames_for, locomotion_plan, times
from controlmm.corpus.families.walking import cadence
from controlmm.corpus.family import Built, Family
from controlmm.corpus.feet import Stance, foot_track
from controlmm.corpus.gait import Gait, RootPath, Step, plan_steps
from controlmm.corpus.rig import SIDE_SIGN
from controlmm.corpus.scene import Box, Scene
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import FORWARD, WALK
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

SIDES = ("left", "right")
OTHER = {"left": "right", "right": "left"}
CLEAR = 0.04
"""Vertical margin (m) a swinging toe or heel keeps above an object."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


@dataclass
class Walkway:
    """Footholds along a straight walking line: distances ``s`` (m) ahead of the start, the feet
    that step there, their surface heights and the lift-off times."""

    s: list[float]
    sides: list[str]
    grounds: list[float]
    t_off: list[float]
    t_on: list[float]


def schedule(
    s: list[float], grounds: list[float], first: str, start: float, step_times: list[float], duty: float
) -> Walkway:
    """Alternate feet from ``first`` over the footholds ``s``: step k lifts off ``step_times[k]``
    seconds before step k + 1, and its swing lasts ``2 (1 - duty) step_times[k]``."""
    sides, t_off, t_on = [], [], []
    cursor = start
    for k, dt in enumerate(step_times):
        sides.append(first if k % 2 == 0 else OTHER[first])
        t_off.append(cursor)
        t_on.append(cursor + 2.0 * (1.0 - duty) * dt)
        cursor += dt
    return Walkway(list(s), sides, list(grounds), t_off, t_on)


def build_walkway(
    rng: np.random.Generator,
    person: Person,
    t: np.ndarray,
    way: Walkway,
    gait: Gait,
    scene: Scene,
    start_ground: float,
    style: Style,
    lateral: dict[str, float] | None = None,
) -> np.ndarray:
    """Joints (T, 22, 3) of a person walking the footholds of ``way`` over ``scene``."""
    n = len(t)
    yaw = person.yaw0
    fwd, left = axes(yaw)
    feet0 = person.initial_feet(np.zeros(2), yaw)
    half = {s: (lateral or {}).get(s, 0.5 * person.width) for s in SIDES}
    steps = [
        Step(
            side,
            t0,
            t1,
            fwd * s_k + SIDE_SIGN[side] * half[side] * left,
            yaw + SIDE_SIGN[side] * person.toe_out,
            ground,
        )
        for s_k, side, ground, t0, t1 in zip(way.s, way.sides, way.grounds, way.t_off, way.t_on, strict=True)
    ]
    stances = plan_steps(feet0, steps, gait, ground={s: start_ground for s in SIDES})
    terrain = scene.terrain(margin=0.03)
    feet = {s: foot_track(s, stances[s], t, terrain, CLEAR) for s in SIDES}
    mid = 0.5 * (feet["left"].ankle + feet["right"].ankle)[:, [0, 2]]
    sigma = 0.35 * (way.t_off[1] - way.t_off[0] if len(way.t_off) > 1 else 0.6) * FPS
    root = gaussian_filter1d(mid, sigma, axis=0, mode="nearest")
    path = RootPath(t=t, xz=root, yaw=np.full(n, yaw))
    plan = locomotion_plan(rng, person, t, path, gait, style, stances=stances)
    plan.feet = feet
    surface = np.stack([_surface(stances[s], t) for s in SIDES])
    level = 0.5 * (surface.max(0) + surface.mean(0))
    plan.pelvis_height = plan.pelvis_height + gaussian_filter1d(level, 0.15 * FPS, mode="nearest")
    return finish(plan)


def _surface(stances: list[Stance], t: np.ndarray) -> np.ndarray:
    """Height (T,) of the surface a foot stands on, blended over each swing."""
    out = np.full(len(t), stances[0].ground)
    for a, b in zip(stances[:-1], stances[1:], strict=True):
        s = smoothstep((t - a.t_off) / max(b.t_on - a.t_off, 1e-3))
        out = np.where(t >= a.t_off, a.ground + (b.ground - a.ground) * s, out)
    return out


def _gait(person: Person, v: float, first: str, duty: float) -> Gait:
    cad = cadence("walk", v)
    return Gait(
        cadence=cad, duty=duty, width=person.width, step_ref=v / cad, toe_out=person.toe_out, first=first
    )


def _box(name: str, yaw: float, s0: float, s1: float, height: float, width: float, base: float = 0.0) -> Box:
    """A box across the walking line from ``s0`` to ``s1`` ahead of the start, ``height`` m tall
    on a surface ``base`` m high."""
    fwd, _ = axes(yaw)
    c = fwd * 0.5 * (s0 + s1)
    return Box(name, (float(c[0]), base + 0.5 * height, float(c[1])), (width, height, s1 - s0), float(yaw))


# step over an obstacle ------------------------------------------------------------------


def _over_sample(rng: np.random.Generator) -> dict:
    v = rng.uniform(0.6, 1.05)
    step = v / cadence("walk", v)
    before = int(rng.integers(1, 4))
    after = int(rng.integers(1, 3))
    return {
        "speed": _r(v),
        "step": _r(step),
        "before": before,
        "after": after,
        "height": _r(rng.uniform(0.12, 0.3)),
        "depth": _r(rng.uniform(0.08, 0.22)),
        "width": _r(rng.uniform(0.6, 1.4)),
        "toe_gap": _r(rng.uniform(0.06, 0.14)),
        "heel_gap": _r(rng.uniform(0.08, 0.16)),
        "idle": _r(rng.uniform(0.2, 0.7)),
        "first": str(rng.choice(SIDES)),
        "stops": bool(rng.random() < 0.6),
        "obstacle": str(rng.choice(["box", "log", "hurdle", "obstacle"])),
    }


def _over_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    person = Person.sample(rng)
    gait = _gait(person, p["speed"], p["first"], 0.62)
    step = p["step"]
    s = [0.6 * step + k * step for k in range(p["before"])]
    o0 = s[-1] + 0.2 + p["toe_gap"]
    o1 = o0 + p["depth"]
    s.append(o1 + 0.05 + p["heel_gap"])  # the leading foot lands beyond the obstacle
    s.append(s[-1] + step)  # the trailing foot swings over it
    for _ in range(p["after"]):
        s.append(s[-1] + step)
    if p["stops"]:
        s.append(s[-1])  # a closing step: the feet end side by side
    step_time = 1.0 / gait_cadence(gait)
    durations = [step_time * (1.3 if k in (p["before"], p["before"] + 1) else 1.0) for k in range(len(s))]
    way = schedule(s, [0.0] * len(s), p["first"], p["idle"], durations, gait.duty)
    seconds = way.t_on[-1] + (0.6 if p["stops"] else 0.1)
    t = times(frames_for(seconds))
    obstacle = _box("obstacle", person.yaw0, o0, o1, p["height"], p["width"])
    scene = Scene("obstacle", (obstacle,), {"obstacle_height": p["height"], "obstacle_depth": p["depth"]})
    style = Style(kind="walk", bob=0.025, lean=0.05)
    return Built(build_walkway(rng, person, t, way, gait, scene, 0.0, style), scene)


def gait_cadence(gait: Gait) -> float:
    """The gait's cadence (steps/s) as a number."""
    return float(np.mean(gait.cadence))


OBSTACLE = {
    "box": ("a low box", "a small box"),
    "log": ("a log", "a fallen log"),
    "hurdle": ("a low hurdle", "a small hurdle"),
    "obstacle": ("a low obstacle", "an obstacle"),
}


FAMILIES.append(
    Family(
        name="step_over",
        group="terrain",
        sample=_over_sample,
        build=_over_build,
        templates=(
            Template("{subj} {walk} {forward} and steps over {thing}"),
            Template("{subj} steps over {thing} on the floor"),
            Template("{subj} lifts {poss} legs high to step over {thing}"),
            Template("walking {forward}, {subj} steps over {thing}"),
            Template("{subj} {walk} {forward}, stepping over {thing} in the way"),
            Template("{subj} clears {thing} with a high step", held=True),
            Template("{subj} carefully crosses over {thing} lying in the path", held=True),
        ),
        slots=lambda p: {
            "walk": WALK,
            "forward": FORWARD,
            "thing": Slot(OBSTACLE[p["obstacle"]], ("a small barrier",)),
        },
        core=lambda p: {"travel": "forward"},
    )
)


# step up onto / down from a platform ----------------------------------------------------


def _platform_sample(rng: np.random.Generator) -> dict:
    v = rng.uniform(0.55, 1.0)
    return {
        "vertical": str(rng.choice(["up", "down"])),
        "speed": _r(v),
        "step": _r(v / cadence("walk", v)),
        "height": _r(rng.uniform(0.14, 0.35)),
        "depth": _r(rng.uniform(0.9, 1.6)),
        "width": _r(rng.uniform(0.8, 1.6)),
        "before": int(rng.integers(0, 3)),
        "edge": _r(rng.uniform(0.12, 0.22)),
        "after": int(rng.integers(0, 2)),
        "idle": _r(rng.uniform(0.2, 0.7)),
        "first": str(rng.choice(SIDES)),
        "kind": str(rng.choice(["platform", "box", "step", "stage"])),
    }


def _platform_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    person = Person.sample(rng)
    gait = _gait(person, p["speed"], p["first"], 0.64)
    step, h = p["step"], p["height"]
    s = [0.6 * step + k * step for k in range(p["before"])]
    last = s[-1] if s else 0.0
    if p["vertical"] == "up":
        edge = last + 0.2 + p["edge"]  # toes of the rear foot to the edge
        lo, hi = 0.0, h
        boxes = (_box("platform", person.yaw0, edge, edge + p["depth"], h, p["width"]),)
        land = edge + 0.1 + p["edge"]
    else:
        edge = last + 0.2 + p["edge"]
        lo, hi = h, 0.0
        boxes = (_box("platform", person.yaw0, -0.6, edge, h, p["width"]),)
        land = edge + 0.1 + p["edge"]
    s.append(land)
    for _ in range(p["after"]):
        s.append(s[-1] + min(step, 0.45))
    s.append(s[-1])  # the other foot closes beside
    grounds = [lo if x < edge else hi for x in s]
    step_time = 1.0 / gait_cadence(gait)
    durations = [step_time * (1.3 if k in (p["before"], p["before"] + 1) else 1.0) for k in range(len(s))]
    way = schedule(s, grounds, p["first"], p["idle"], durations, gait.duty)
    t = times(frames_for(way.t_on[-1] + 0.7))
    scene = Scene("platform", boxes, {"platform_height": h, "direction": p["vertical"]})
    style = Style(kind="walk", bob=0.02, lean=0.08 if p["vertical"] == "up" else 0.03)
    return Built(build_walkway(rng, person, t, way, gait, scene, lo, style), scene)


PLATFORM = {"platform": "platform", "box": "box", "step": "step", "stage": "stage"}


def _platform_slots(p: dict) -> dict[str, Slot]:
    thing = PLATFORM[p["kind"]]
    if p["vertical"] == "up":
        move = Slot(("steps up onto", "climbs onto", "steps onto"), ("gets up on",), ("vertical", "up"))
    else:
        move = Slot(
            ("steps down from", "steps off", "climbs down from"), ("gets down from",), ("vertical", "down")
        )
    return {"move": move, "thing": Slot((f"a {thing}", f"the {thing}"), (f"a raised {thing}",))}


FAMILIES.append(
    Family(
        name="platform",
        group="terrain",
        sample=_platform_sample,
        build=_platform_build,
        templates=(
            Template("{subj} {move} {thing}"),
            Template("{subj} walks forward and {move} {thing}"),
            Template("{subj} {move} {thing} with one foot after the other"),
            Template("{subj} carefully {move} {thing}"),
            Template("{subj} takes a step and {move} {thing}"),
            Template("{subj} {move} {thing} in front of {poss} feet", held=True),
            Template("one foot at a time, {subj} {move} {thing}", held=True),
        ),
        slots=_platform_slots,
        core=lambda p: {},
    )
)


# stairs ---------------------------------------------------------------------------------


def _stairs_sample(rng: np.random.Generator) -> dict:
    n = int(rng.integers(3, 7))
    return {
        "vertical": str(rng.choice(["up", "down"])),
        "steps": n,
        "riser": _r(rng.uniform(0.12, 0.19)),
        "tread": _r(rng.uniform(0.26, 0.33)),
        "width": _r(rng.uniform(0.9, 1.5)),
        "cadence": _r(rng.uniform(1.45, 1.85)),
        "before": int(rng.integers(0, 3)),
        "after": int(rng.integers(0, 2)),
        "gap": _r(rng.uniform(0.08, 0.18)),
        "idle": _r(rng.uniform(0.2, 0.6)),
        "first": str(rng.choice(SIDES)),
    }


def _stairs_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    person = Person.sample(rng)
    n, r, d = p["steps"], p["riser"], p["tread"]
    v_flat = 0.8
    step = v_flat / cadence("walk", v_flat)
    gait = Gait(
        cadence=p["cadence"],
        duty=0.64,
        width=person.width,
        step_ref=0.55,
        toe_out=person.toe_out,
        first=p["first"],
    )
    s = [0.6 * step + k * step for k in range(p["before"])]
    last = s[-1] if s else 0.0
    x0 = last + 0.2 + p["gap"]  # the first riser (up) or the top edge (down), ahead of the toes
    up = p["vertical"] == "up"
    boxes = []
    if up:
        for k in range(1, n + 1):
            depth = d if k < n else 1.0  # the top step is the landing
            boxes.append(
                _box(f"step {k}", person.yaw0, x0 + (k - 1) * d, x0 + (k - 1) * d + depth, k * r, p["width"])
            )
        treads = [x0 + (k - 1) * d + 0.5 * d - 0.05 for k in range(1, n + 1)]
        heights = [k * r for k in range(1, n + 1)]
        start_ground = 0.0
    else:
        boxes.append(_box("landing", person.yaw0, -0.8, x0, n * r, p["width"]))
        for k in range(1, n):
            boxes.append(
                _box(f"step {k}", person.yaw0, x0 + (k - 1) * d, x0 + k * d, (n - k) * r, p["width"])
            )
        treads = [x0 + (k - 1) * d + 0.5 * d - 0.02 for k in range(1, n)]
        treads.append(x0 + (n - 1) * d + 0.28)  # the floor beyond the last step
        heights = [(n - k) * r for k in range(1, n + 1)]
        start_ground = n * r
    grounds = [start_ground] * len(s) + heights
    s = s + treads
    level = heights[-1]
    if p["after"]:
        s.append(s[-1] + 0.45)
        grounds.append(level)
    s.append(s[-1])  # the other foot closes beside
    grounds.append(level)
    flat_time = 1.0 / cadence("walk", v_flat)
    durations = [flat_time if k < p["before"] else 1.0 / p["cadence"] for k in range(len(s))]
    way = schedule(s, grounds, p["first"], p["idle"], durations, gait.duty)
    t = times(frames_for(way.t_on[-1] + 0.6))
    kind = "stairs"
    scene = Scene(
        kind, tuple(boxes), {"steps": n, "step_height": r, "step_depth": d, "direction": p["vertical"]}
    )
    style = Style(kind="walk", bob=0.015, drop=0.02, lean=0.12 if up else 0.04, arm_swing=0.6)
    return Built(build_walkway(rng, person, t, way, gait, scene, start_ground, style), scene)


def _stairs_slots(p: dict) -> dict[str, Slot]:
    if p["vertical"] == "up":
        move = Slot(("walks up", "climbs up", "goes up", "climbs"), ("ascends",), ("vertical", "up"))
    else:
        move = Slot(("walks down", "goes down", "comes down"), ("descends",), ("vertical", "down"))
    n = p["steps"]
    words = {3: "three", 4: "four", 5: "five", 6: "six"}[n]
    return {
        "move": move,
        "stairs": Slot(("the stairs", "a flight of stairs", "the steps"), ("a staircase",)),
        "count": Slot((f"{words} steps",), (f"{n} steps",)),
    }


FAMILIES.append(
    Family(
        name="stairs",
        group="terrain",
        sample=_stairs_sample,
        build=_stairs_build,
        templates=(
            Template("{subj} {move} {stairs}"),
            Template("{subj} {move} {stairs}, one step at a time"),
            Template("{subj} {move} {count}"),
            Template("{subj} {move} a short flight of {count}"),
            Template("{subj} walks forward and {move} {stairs}"),
            Template("{subj} {move} {stairs} at a steady pace", held=True),
            Template("step by step, {subj} {move} {stairs}", held=True),
        ),
        slots=_stairs_slots,
        core=lambda p: {},
    )
)
