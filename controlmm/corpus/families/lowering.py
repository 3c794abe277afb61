"""Going low: squats (n times) and kneeling on one knee."""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import keyframes
from controlmm.corpus.families.base import Person, finish, frames_for, standing_plan, times
from controlmm.corpus.family import Family
from controlmm.corpus.feet import Stance, foot_track
from controlmm.corpus.rig import KNEE_INDEX, SIDE_SIGN, heading_vectors
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import counted_slot, times_slot

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

KNEE_ON_FLOOR = 0.06
"""Height (m) of the knee joint centre when the knee rests on the floor."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


# squat ------------------------------------------------------------------------------------


def _squat_sample(rng):
    n = int(rng.choice([1, 2, 3], p=[0.45, 0.35, 0.2]))
    for _ in range(50):
        down, hold, up, rest = (
            rng.uniform(0.6, 1.1),
            rng.uniform(0.1, 0.7),
            rng.uniform(0.5, 0.9),
            rng.uniform(0.15, 0.5),
        )
        idle = rng.uniform(0.3, 1.0)
        seconds = idle + n * (down + hold + up) + (n - 1) * rest + rng.uniform(0.4, 1.0)
        if seconds <= 9.7:
            break
        n = max(1, n - 1)
    return {
        "count": n,
        "depth": _r(rng.uniform(0.3, 0.48)),
        "down": _r(down),
        "hold": _r(hold),
        "up": _r(up),
        "rest": _r(rest),
        "idle": _r(idle),
        "seconds": _r(max(seconds, 2.2)),
        "arms": str(rng.choice(["forward", "low"])),
    }


def squat_keys(p: dict, start: float, stand: float) -> tuple[list[float], list[float], list[float]]:
    """Key times, pelvis heights and depth fractions of ``count`` squats from ``start``."""
    ts, hs, fr = [start], [stand], [0.0]
    cursor = start
    for _ in range(p["count"]):
        bottom = cursor + p["down"]
        ts += [bottom, bottom + p["hold"], bottom + p["hold"] + p["up"]]
        hs += [stand - p["depth"], stand - p["depth"], stand]
        fr += [1.0, 1.0, 0.0]
        cursor = ts[-1] + p["rest"]
    return ts, hs, fr


def _squat_build(p, rng):
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    person.width = rng.uniform(0.26, 0.38)
    person.toe_out = rng.uniform(0.15, 0.35)
    plan = standing_plan(rng, person, t)
    apply_squats(plan, p, t, p["idle"], person)
    return finish(plan)


def apply_squats(plan, p: dict, t: np.ndarray, start: float, person: Person) -> None:
    """Lower and raise the pelvis ``count`` times, sitting back with the chest forward."""
    ts, hs, fr = squat_keys(p, start, person.stand_height)
    height = keyframes(t, ts, hs)
    frac = keyframes(t, ts, fr)
    plan.pelvis_height = np.minimum(plan.pelvis_height, height)
    shift = plan.get_shift()
    shift[:, 2] += -0.16 * frac * (p["depth"] / 0.4)
    plan.pelvis_shift = shift
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.35 * frac
    plan.spine_pitch = plan.get("spine_pitch") + 0.25 * frac
    plan.head_pitch = plan.get("head_pitch") - 0.35 * frac
    plan.knee_out = 0.35
    for side in ("left", "right"):
        arm = plan.arms[side]
        if p["arms"] == "forward":
            arm.flex = arm.flex + 1.35 * frac
            arm.elbow = arm.elbow * (1.0 - 0.6 * frac)
        else:
            arm.flex = arm.flex + 0.45 * frac
            arm.elbow = arm.elbow + 0.6 * frac


FAMILIES.append(
    Family(
        name="squat",
        group="lowering",
        sample=_squat_sample,
        build=_squat_build,
        templates=(
            Template("{subj} squats {times}"),
            Template("{subj} does {squats}"),
            Template("{subj} squats down and stands back up {times}"),
            Template("{subj} bends {poss} knees and squats {times}"),
            Template("{subj} performs {squats}"),
            Template("{subj} lowers into a deep squat and rises {times}", held=True),
            Template("{subj} completes {squats} in place", held=True),
        ),
        slots=lambda p: {
            "times": times_slot(p["count"]),
            "squats": counted_slot(p["count"], "squat", "squats"),
        },
        core=lambda p: {"count": p["count"]},
    )
)


# kneel ------------------------------------------------------------------------------------


def _kneel_sample(rng):
    stand_up = bool(rng.random() < 0.5)
    idle, step, down, hold = rng.uniform(0.3, 0.9), 0.55, rng.uniform(0.8, 1.3), rng.uniform(0.8, 2.5)  # s
    up = rng.uniform(0.8, 1.2) if stand_up else 0.0
    seconds = idle + step + down + hold + up + (0.9 if stand_up else 0.2)
    return {
        "knee": str(rng.choice(["left", "right"])),
        "stand_up": stand_up,
        "idle": _r(idle),
        "back": _r(rng.uniform(0.55, 0.7)),
        "down": _r(down),
        "hold": _r(hold),
        "up": _r(up),
        "seconds": _r(min(seconds, 9.8)),
    }


def _kneel_build(p, rng):
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    knee, front = p["knee"], "left" if p["knee"] == "right" else "right"
    fwd, left = heading_vectors(np.array(person.yaw0))
    fwd2, left2 = fwd[[0, 2]], left[[0, 2]]
    feet0 = person.initial_feet(np.zeros(2), person.yaw0)
    t_lift = p["idle"]
    t_land = t_lift + 0.55
    t_bottom = t_land + p["down"]
    t_rise = t_bottom + p["hold"]
    t_up = t_rise + p["up"]

    rear_home, rear_yaw = feet0[knee]
    rear_xz = rear_home - p["back"] * fwd2 + SIDE_SIGN[knee] * 0.03 * left2
    tuck = -1.1
    rear = [Stance(-np.inf, t_lift, rear_home, rear_yaw, lift_pitch=-0.2, lift_time=0.15)]
    back = Stance(t_land, np.inf, rear_xz, rear_yaw, land_pitch=-0.25, land_time=0.1, clearance=0.07)
    keys = [(t_land + 0.1, 0.0), (t_bottom, tuck)]
    if p["stand_up"]:
        keys += [(t_rise, tuck), (t_up - 0.2, -0.5)]
        back.t_off = t_up - 0.2
        rear.append(back)
        rear.append(
            Stance(t_up + 0.25, np.inf, rear_home, rear_yaw, land_pitch=0.15, land_time=0.1, clearance=0.07)
        )
    else:
        rear.append(back)
    back.pitch_keys = keys
    stances = {knee: rear, front: [Stance(-np.inf, np.inf, feet0[front][0], feet0[front][1])]}

    plan = standing_plan(rng, person, t, stances=stances)
    plan.feet = {s: foot_track(s, stances[s], t) for s in stances}
    plan.root_xz = np.tile(0.5 * (feet0["left"][0] + feet0["right"][0]), (n, 1))
    stand = person.stand_height
    key_t = [t_lift, t_land, t_bottom, t_rise, t_up]
    back_shift = p["back"] - 0.5  # the hip ends ~0.4 m ahead of the tucked rear ankle
    shift_z = (
        [0.0, -0.15, -back_shift, -back_shift, 0.0]
        if p["stand_up"]
        else [0.0, -0.15, -back_shift, -back_shift, -back_shift]
    )
    frac = keyframes(t, key_t, [0.0, 0.1, 1.0, 1.0, 0.0 if p["stand_up"] else 1.0])
    shift = plan.get_shift()
    shift[:, 2] += keyframes(t, key_t, shift_z)
    plan.pelvis_shift = shift
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.05 * frac
    plan.spine_pitch = plan.get("spine_pitch") + 0.12 * frac
    for side in ("left", "right"):
        plan.arms[side].flex = plan.arms[side].flex + (0.35 if side == front else 0.1) * frac
        plan.arms[side].elbow = plan.arms[side].elbow + (0.5 if side == front else 0.1) * frac
    # Lower the pelvis until the rear knee touches the floor (two refinements).
    low = stand - 0.4
    for _ in range(3):
        plan.pelvis_height = stand - (stand - low) * frac
        joints = finish(plan)
        at_bottom = (t >= t_bottom) & (t <= t_rise)
        knee_y = joints[at_bottom, KNEE_INDEX[knee], 1].mean()
        low -= knee_y - KNEE_ON_FLOOR
    plan.pelvis_height = stand - (stand - low) * frac
    return finish(plan)


FAMILIES.append(
    Family(
        name="kneel",
        group="lowering",
        sample=_kneel_sample,
        build=_kneel_build,
        templates=(
            Template("{subj} kneels down on {poss} {knee}{rise}"),
            Template("{subj} steps back and goes down on {poss} {knee}{rise}"),
            Template("{subj} drops to {poss} {knee}{rise}"),
            Template("{subj} gets down on one knee, the {knee_side} one{rise}"),
            Template("{subj} lowers {poss} {knee} to the ground{rise}"),
            Template("{subj} takes a knee, resting on {poss} {knee}{rise}", held=True),
            Template("{subj} sinks onto {poss} {knee}{rise}", held=True),
        ),
        slots=lambda p: {
            "knee": Slot((f"{p['knee']} knee",), (), ("knee", p["knee"])),
            "knee_side": Slot((p["knee"],), (), ("knee", p["knee"])),
            "rise": (
                Slot(
                    (" and then stands back up", " and gets up again", ", then rises"),
                    (" before standing up again",),
                    ("stand_up", True),
                )
                if p["stand_up"]
                else Slot(("", " and stays there"), (" and remains kneeling",), ("stand_up", False))
            ),
        },
        core=lambda p: {"knee": p["knee"]},
    )
)
