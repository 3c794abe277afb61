"""Reaching out while standing: reach forward, up or sideways, punch.

Wrist targets are relative to the shoulder in the chest frame (see
:mod:`controlmm.corpus.families.gestures`).
"""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import keyframes
from controlmm.corpus.families.base import Person, finish, frames_for, set_ik, standing_plan, times
from controlmm.corpus.families.gestures import OTHER, gesture_timing, gesture_window, pole, target
from controlmm.corpus.family import Family
from controlmm.corpus.feet import Stance, foot_track
from controlmm.corpus.rig import SIDE_SIGN
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import counted_slot, hand_slot, times_slot

FAMILIES: list[Family] = []
"""This module's families, in registry order."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


# reach ------------------------------------------------------------------------------------


def _reach_sample(rng, both: bool = False):
    p = gesture_timing(rng, rng.uniform(0.4, 1.6))
    p["hand"] = str(rng.choice(["left", "right", "both"] if both else ["left", "right"]))
    return p


def _reach_builder(kind: str):
    def build(p, rng):
        t = times(frames_for(p["seconds"]))
        n = len(t)
        person = Person.sample(rng)
        w, a, b = gesture_window(p, t)
        stances = None
        if kind == "up":
            feet0 = person.initial_feet(np.zeros(2), person.yaw0)
            rise = [(p["idle"], 0.0), (a, -0.35), (b, -0.35), (b + p["fall"], 0.0)]
            stances = {s: [Stance(-np.inf, np.inf, feet0[s][0], feet0[s][1], pitch_keys=rise)] for s in feet0}
        plan = standing_plan(rng, person, t, stances=stances)
        if stances is not None:
            plan.feet = {s: foot_track(s, stances[s], t) for s in stances}
            plan.pelvis_height = plan.pelvis_height + 0.07 * w
            plan.head_pitch = plan.get("head_pitch") - 0.3 * w
        hands = ("left", "right") if p["hand"] == "both" else (p["hand"],)
        for side in hands:
            s = SIDE_SIGN[side]
            if kind == "forward":
                set_ik(plan.arms[side], w, target(side, -0.06, -0.02, 0.51, n), pole(side, 0.7, -1.0, 0.0, n))
                plan.spine_pitch = plan.get("spine_pitch") + 0.2 * w / len(hands)
                plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.1 * w / len(hands)
            elif kind == "up":
                set_ik(
                    plan.arms[side],
                    w,
                    target(side, 0.05, 0.51, 0.1, n),
                    pole(side, 1.0, 0.0, -0.4, n),
                    elevation=np.full(n, 0.35),
                    arc=(0, 0, 0.3),
                )
            else:
                set_ik(
                    plan.arms[side],
                    w,
                    target(side, 0.51, 0.02, 0.06, n),
                    pole(side, 0.0, -0.3, -1.0, n),
                    elevation=np.full(n, 0.15),
                )
                plan.spine_roll = plan.get("spine_roll") + s * 0.22 * w
                plan.pelvis_roll = plan.get("pelvis_roll") + s * 0.05 * w
        return finish(plan)

    return build


REACH = Slot(("reaches", "stretches", "extends"), ("stretches out",))


def _reach_slots(p):
    hand = (
        Slot(("both arms", "both hands"), (), ("hand", "both"))
        if p["hand"] == "both"
        else hand_slot(p["hand"])
    )
    return {"reach": REACH, "hand": hand}


FAMILIES.append(
    Family(
        name="reach_forward",
        group="reaching",
        sample=_reach_sample,
        build=_reach_builder("forward"),
        templates=(
            Template("{subj} {reach} {poss} {hand} forward"),
            Template("{subj} reaches forward with {poss} {hand}"),
            Template("{subj} {reach} {poss} {hand} out in front to grab something"),
            Template("{subj} leans forward and reaches out with {poss} {hand}"),
            Template("{subj} extends {poss} {hand} straight ahead"),
            Template("{subj} tries to touch something in front using {poss} {hand}", held=True),
            Template("{subj} stretches out {poss} {hand} toward an object ahead", held=True),
        ),
        slots=_reach_slots,
        core=lambda p: {"hand": p["hand"], "reach": "forward"},
    )
)

FAMILIES.append(
    Family(
        name="reach_up",
        group="reaching",
        sample=lambda rng: _reach_sample(rng, both=True),
        build=_reach_builder("up"),
        templates=(
            Template("{subj} {reach} {poss} {hand} up high"),
            Template("{subj} reaches up with {poss} {hand}"),
            Template("{subj} stands on tiptoes and reaches up with {poss} {hand}"),
            Template("{subj} {reach} {poss} {hand} upward to get something from a shelf"),
            Template("{subj} reaches for something above {poss} head with {poss} {hand}"),
            Template("on {poss} toes, {subj} stretches {poss} {hand} toward the ceiling", held=True),
            Template("{subj} grabs at something overhead using {poss} {hand}", held=True),
        ),
        slots=_reach_slots,
        core=lambda p: {"hand": p["hand"], "reach": "up"},
    )
)

FAMILIES.append(
    Family(
        name="reach_sideways",
        group="reaching",
        sample=_reach_sample,
        build=_reach_builder("side"),
        templates=(
            Template("{subj} {reach} {poss} {hand} out to the side"),
            Template("{subj} reaches sideways with {poss} {hand}"),
            Template("{subj} leans to the {side} and reaches out with {poss} {hand}"),
            Template("{subj} {reach} {poss} {hand} out to the {side}"),
            Template("{subj} extends {poss} {hand} sideways"),
            Template("{subj} bends to the {side} stretching {poss} {hand} away from the body", held=True),
            Template("{subj} reaches for something at {poss} {side} side with {poss} {hand}", held=True),
        ),
        slots=lambda p: dict(_reach_slots(p), side=Slot((p["hand"],), (), ("side", p["hand"]))),
        core=lambda p: {"hand": p["hand"], "reach": "side"},
    )
)


# punch ------------------------------------------------------------------------------------


def _punch_sample(rng):
    count = int(rng.integers(1, 5))
    gaps = [rng.uniform(0.25, 0.6) for _ in range(count)]
    p = gesture_timing(rng, sum(gaps) + 0.3 * count + 0.2)
    p.update({"hand": str(rng.choice(["left", "right"])), "count": count, "gaps": [_r(g) for g in gaps]})
    return p


def _punch_build(p, rng):
    t = times(frames_for(p["seconds"]))
    n = len(t)
    person = Person.sample(rng)
    person.stagger = SIDE_SIGN[p["hand"]] * rng.uniform(0.15, 0.25)
    plan = standing_plan(rng, person, t)
    w, a, b = gesture_window(p, t)
    side, other = p["hand"], OTHER[p["hand"]]
    # Guard: both fists in front of the chin; the punching fist shoots out and comes back.
    ext_t, ext_v = [a], [0.0]
    cursor = a + 0.1
    for g in p["gaps"]:
        ext_t += [cursor + 0.13, cursor + 0.2, cursor + 0.42]
        ext_v += [1.0, 1.0, 0.0]
        cursor += 0.42 + g
    ext = keyframes(t, ext_t, ext_v)
    guard = target(side, -0.1, 0.05, 0.22, n)
    strike = target(side, -0.12, 0.04, 0.5, n)
    set_ik(plan.arms[side], w, guard + ext[:, None] * (strike - guard), pole(side, 0.6, -1.0, -0.2, n))
    set_ik(plan.arms[other], w, target(other, -0.1, 0.07, 0.2, n), pole(other, 0.6, -1.0, -0.2, n))
    plan.spine_twist = plan.get("spine_twist") - SIDE_SIGN[side] * 0.3 * ext
    plan.pelvis_twist = plan.get("pelvis_twist") - SIDE_SIGN[side] * 0.1 * ext
    plan.spine_pitch = plan.get("spine_pitch") + 0.08 * w
    return finish(plan)


FAMILIES.append(
    Family(
        name="punch",
        group="reaching",
        sample=_punch_sample,
        build=_punch_build,
        templates=(
            Template("{subj} punches {times} with {poss} {hand}"),
            Template("{subj} throws {punches} with {poss} {hand}"),
            Template("{subj} raises {poss} fists and punches {times} with the {hand}"),
            Template("{subj} boxes, hitting forward {times} with {poss} {hand}"),
            Template("{subj} jabs {times} using {poss} {hand}"),
            Template("in a fighting stance, {subj} strikes {times} with {poss} {hand}", held=True),
            Template("{subj} lands {punches} with {poss} {hand} fist", held=True),
        ),
        slots=lambda p: {
            "times": times_slot(p["count"]),
            "punches": counted_slot(p["count"], "punch", "punches"),
            "hand": hand_slot(p["hand"]),
        },
        core=lambda p: {"hand": p["hand"], "count": p["count"]},
    )
)
