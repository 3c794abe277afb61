"""Sequences of two actions with a walk: walk to a seat, turn and sit down; walk then kick; walk
then bow; pick something up and walk away carrying it."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import ramp, window
from controlmm.corpus.families.actions import add_kicks, kick_body, kick_slots, kick_time, sample_kick
from controlmm.corpus.families.base import Person, Style, finish, frames_for, locomotion_plan, times
from controlmm.corpus.families.postures import (
    apply_bow,
    apply_pick,
    apply_sit,
    pick_slots,
    sample_pick,
    sample_sit,
    seat_slot,
)
from controlmm.corpus.families.walking import cadence, walk_duty
from controlmm.corpus.family import Built, Family
from controlmm.corpus.gait import Gait, RootPath, plan_footholds
from controlmm.corpus.scene import Scene
from controlmm.corpus.text.templates import Template
from controlmm.corpus.text.vocab import FORWARD, WALK, counted_slot, times_slot
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


def _walk(rng: np.random.Generator) -> dict:
    """A walk from standing that stops: speed, start, cruise and ease times (s)."""
    return {
        "speed": _r(rng.uniform(0.8, 1.3)),
        "idle": _r(rng.uniform(0.0, 0.5)),
        "walk": _r(rng.uniform(1.8, 3.2)),
        "ease": _r(rng.uniform(0.5, 0.8)),
        "first": str(rng.choice(["left", "right"])),
    }


def _walk_gait(
    person: Person, v: float, first: str, start: float, cad: float | np.ndarray | None = None
) -> Gait:
    c = cadence("walk", v)
    return Gait(
        cadence=c if cad is None else cad,
        duty=walk_duty(v),
        width=person.width,
        step_ref=v / c,
        toe_out=person.toe_out,
        first=first,
        start=max(start, 0.0),
    )


def _walk_end(p: dict) -> float:
    """When the walk has stopped (s)."""
    return p["idle"] + p["walk"] + p["ease"]


def _walk_path(t: np.ndarray, p: dict, yaw: np.ndarray) -> RootPath:
    speed = p["speed"] * window(t, p["idle"], p["idle"] + p["walk"] + p["ease"], p["ease"])
    return RootPath.from_velocity(t, speed, 0.0, yaw, FPS)


# walk, turn around and sit down ---------------------------------------------------------


def _walksit_sample(rng: np.random.Generator) -> dict:
    p = _walk(rng)
    p["turn"] = str(rng.choice(["left", "right"]))
    p["turn_time"] = _r(rng.uniform(1.3, 1.9))
    p["sit"] = sample_sit(rng, stand_up=False)
    end = _walk_end(p) + 0.1 + p["turn_time"] + 0.3 + p["sit"]["down"] + p["sit"]["hold"]
    p["seconds"] = _r(min(end, 9.8))
    return p


def _walksit_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    stop = _walk_end(p)
    t0, t1 = stop + 0.1, stop + 0.1 + p["turn_time"]
    sign = 1.0 if p["turn"] == "left" else -1.0
    yaw = person.yaw0 + sign * np.pi * ramp(t, t0, t1)
    path = _walk_path(t, p, yaw)
    cad = np.where(t < stop - 0.2, cadence("walk", p["speed"]), 1.9)
    gait = _walk_gait(person, p["speed"], p["first"], p["idle"] - 0.05, cad)
    gait.min_turn = 0.1
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
    seat = apply_sit(plan, p["sit"], t, t1 + 0.3, person, float(yaw[-1]))
    scene = Scene("seat", (seat,), {"seat_height": p["sit"]["seat_height"], "seat": p["sit"]["seat"]})
    return Built(finish(plan), scene)


FAMILIES.append(
    Family(
        name="walk_then_sit",
        group="sequences",
        sample=_walksit_sample,
        build=_walksit_build,
        templates=(
            Template("{subj} {walk} {forward}, turns around and sits down on {seat}"),
            Template("{subj} walks over to {seat}, turns and sits on it"),
            Template("{subj} {walk} {forward} to {seat} and takes a seat"),
            Template("after walking {forward}, {subj} turns around and sits on {seat}"),
            Template("{subj} approaches {seat}, turns around and sits down"),
            Template("{subj} strolls up to {seat} and settles onto it", held=True),
            Template("{subj} heads over to {seat} and sits down to rest", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, "seat": seat_slot(p["sit"])},
        core=lambda p: {"travel": "forward", "stand_up": False},
    )
)


# walk then kick -------------------------------------------------------------------------


def _walkkick_sample(rng: np.random.Generator) -> dict:
    p = _walk(rng)
    p["kick"] = sample_kick(rng)
    p["seconds"] = _r(min(_walk_end(p) + 0.3 + kick_time(p["kick"]) + rng.uniform(0.5, 1.0), 9.8))
    return p


def _walkkick_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    yaw = np.full(len(t), person.yaw0)
    path = _walk_path(t, p, yaw)
    gait = _walk_gait(person, p["speed"], p["first"], p["idle"] - 0.05)
    stances = plan_footholds(path, gait, float(FPS), initial=person.initial_feet(path.xz[0], person.yaw0))
    start = _walk_end(p) + 0.3
    kicks = add_kicks(stances, p["kick"], start, person.yaw0, person.stand_height)
    plan = locomotion_plan(
        rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04), stances=stances
    )
    kick_body(plan, p["kick"], t, start, kicks)
    return finish(plan)


FAMILIES.append(
    Family(
        name="walk_then_kick",
        group="sequences",
        sample=_walkkick_sample,
        build=_walkkick_build,
        templates=(
            Template("{subj} {walk} {forward}, stops and kicks {kind} with {poss} {leg}"),
            Template("{subj} {walk} {forward} and then kicks {kind} {times} with the {leg}"),
            Template("after walking {forward}, {subj} does {kicks} with {poss} {leg}"),
            Template("{subj} takes a few steps {forward} and kicks with {poss} {leg}"),
            Template("{subj} {walk} {forward}, halts, then kicks {kind} using {poss} {leg}"),
            Template("{subj} strolls {forward}, then throws {kicks} {kind} with {poss} {leg}", held=True),
            Template("a short walk {forward} ends as {subj} kicks {kind} with the {leg}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, **kick_slots(p["kick"])},
        core=lambda p: {"travel": "forward", "leg": p["kick"]["leg"]},  # count: from {times} / {kicks}
    )
)


# walk then bow --------------------------------------------------------------------------


def _walkbow_sample(rng: np.random.Generator) -> dict:
    p = _walk(rng)
    count = int(rng.choice([1, 2], p=[0.75, 0.25]))
    p["bow"] = {
        "count": count,
        "arms": str(rng.choice(["sides", "hang", "front"])),
        "bows": [
            {
                "depth": _r(rng.uniform(0.6, 1.05)),
                "down": _r(rng.uniform(0.6, 1.0)),
                "hold": _r(rng.uniform(0.2, 0.8)),
                "up": _r(rng.uniform(0.6, 1.0)),
                "rest": _r(rng.uniform(0.3, 0.6)),
            }
            for _ in range(count)
        ],
    }
    bows = sum(b["down"] + b["hold"] + b["up"] + b["rest"] for b in p["bow"]["bows"])
    p["count"] = count
    p["seconds"] = _r(min(_walk_end(p) + 0.3 + bows + rng.uniform(0.2, 0.6), 9.8))
    return p


def _walkbow_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    path = _walk_path(t, p, np.full(len(t), person.yaw0))
    gait = _walk_gait(person, p["speed"], p["first"], p["idle"] - 0.05)
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.03, lean=0.04))
    apply_bow(plan, p["bow"], t, _walk_end(p) + 0.3)
    return finish(plan)


FAMILIES.append(
    Family(
        name="walk_then_bow",
        group="sequences",
        sample=_walkbow_sample,
        build=_walkbow_build,
        templates=(
            Template("{subj} {walk} {forward}, stops and bows {times}"),
            Template("{subj} {walk} {forward} and then takes {bows}"),
            Template("after walking {forward}, {subj} bows {times}"),
            Template("{subj} walks up, stops and bows forward {times}"),
            Template("{subj} {walk} {forward} before bowing {times}"),
            Template("{subj} approaches someone and greets them with {bows}", held=True),
            Template("{subj} strolls {forward}, halts and bends forward in {bows}", held=True),
        ),
        slots=lambda p: {
            "walk": WALK,
            "forward": FORWARD,
            "times": times_slot(p["count"]),
            "bows": counted_slot(p["count"], "bow", "bows"),
        },
        core=lambda p: {"travel": "forward", "count": p["count"]},
    )
)


# pick something up and carry it ---------------------------------------------------------


def _pickcarry_sample(rng: np.random.Generator) -> dict:
    pick = sample_pick(rng)
    pick["hand"] = "both"
    idle = rng.uniform(0.3, 0.8)
    walk = rng.uniform(2.0, 4.0)
    v = rng.uniform(0.7, 1.15)
    ease = rng.uniform(0.5, 0.8)
    seconds = idle + pick["down"] + pick["grab"] + pick["up"] + 0.2 + walk + ease + rng.uniform(0.0, 0.6)
    return {
        "pick": pick,
        "idle": _r(idle),
        "speed": _r(v),
        "walk": _r(walk),
        "ease": _r(ease),
        "first": str(rng.choice(["left", "right"])),
        "seconds": _r(min(seconds, 9.8)),
    }


def _pickcarry_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    n = len(t)
    person = Person.sample(rng)
    pick = p["pick"]
    if pick["style"] == "squat":
        person.width = rng.uniform(0.24, 0.32)
    go = p["idle"] + pick["down"] + pick["grab"] + pick["up"] + 0.2
    speed = p["speed"] * window(t, go, t[-1] + 5.0, p["ease"])
    path = RootPath.from_velocity(t, speed, 0.0, np.full(n, person.yaw0), FPS)
    gait = _walk_gait(person, p["speed"], p["first"], go - 0.05)
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.025, lean=0.0, arm_swing=0.0))
    obj = apply_pick(plan, pick, t, p["idle"], person, person.yaw0)
    return Built(finish(plan), Scene("object", (obj,), {"object_size": pick["size"]}))


FAMILIES.append(
    Family(
        name="pick_up_and_carry",
        group="sequences",
        sample=_pickcarry_sample,
        build=_pickcarry_build,
        templates=(
            Template("{subj} {how}, picks up {thing} and carries it {forward}"),
            Template("{subj} picks {thing} up off the floor and walks {forward} with it"),
            Template("{subj} {how} to lift {thing}, then {walk} {forward} holding it"),
            Template("{subj} grabs {thing} from the ground and carries it away"),
            Template("{subj} {how}, lifts {thing} with both hands and walks off {forward}"),
            Template("{subj} collects {thing} from the floor and takes it along {forward}", held=True),
            Template("after picking up {thing}, {subj} hauls it {forward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, **pick_slots(p["pick"])},
        core=lambda p: {"travel": "forward", "carry": True},
    )
)
