"""Actions of the legs, arms and head: kick, stretch the arms out to the sides, push with both
hands, look around, point at something, carry something while walking.

Wrist targets are relative to the shoulder in the chest frame (see
:mod:`controlmm.corpus.families.gestures`); kicks plan the kicking foot's path in the person's
ground frame (forward and left of the heading).
"""

from __future__ import annotations

import numpy as np

from controlmm.corpus.body import BodyPlan
from controlmm.corpus.curves import keyframes, window
from controlmm.corpus.families.base import (
    Person,
    Style,
    axes,
    finish,
    frames_for,
    locomotion_plan,
    set_ik,
    standing_plan,
    times,
)
from controlmm.corpus.families.gestures import OTHER, gesture_timing, gesture_window, pole, target
from controlmm.corpus.families.walking import _sample_travel, cadence, walk_duty
from controlmm.corpus.family import Family
from controlmm.corpus.feet import ANKLE_HEIGHT, Stance, foot_track
from controlmm.corpus.gait import Gait, RootPath
from controlmm.corpus.rig import SHIN, SIDE_SIGN, THIGH
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import FORWARD, WALK, counted_slot, hand_slot, times_slot
from controlmm.motion.skeleton import FPS

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

SIDES = ("left", "right")


def _r(x: float) -> float:
    return float(round(float(x), 4))


# kick -----------------------------------------------------------------------------------


def sample_kick(rng: np.random.Generator) -> dict:
    """Leg, kind, height and timing of one or two kicks."""
    kind = str(rng.choice(["front", "side"]))
    count = int(rng.choice([1, 2], p=[0.7, 0.3]))
    return {
        "leg": str(rng.choice(SIDES)),
        "kind": kind,
        "count": count,
        "height": _r(rng.uniform(0.45, 0.85) if kind == "front" else rng.uniform(0.38, 0.6)),
        "shift": _r(rng.uniform(0.45, 0.7)),
        "kick": _r(rng.uniform(0.75, 1.05)),
        "between": _r(rng.uniform(0.35, 0.7)),
    }


def kick_time(p: dict) -> float:
    """Seconds from the weight shift to the last kick's landing."""
    return p["shift"] + p["count"] * p["kick"] + (p["count"] - 1) * p["between"]


def add_kicks(
    stances: dict[str, list[Stance]], p: dict, start: float, yaw: float, stand_height: float
) -> list[tuple[float, float]]:
    """Replace the kicking foot's last stance from ``start`` with ``count`` kicks that land back
    on the same spot; returns the (lift-off, landing) times."""
    leg = p["leg"]
    fwd, left = axes(yaw)
    home = stances[leg][-1]
    other = stances[OTHER[leg]][-1]
    sign = SIDE_SIGN[leg]
    hip_y = stand_height - 0.1
    length = 0.93 * (THIGH[leg] + SHIN[leg])
    h = p["height"]
    reach = float(np.sqrt(max(length**2 - (hip_y - h) ** 2, 0.04)))
    # The hip sits over the midpoint of the feet shifted towards the standing foot.
    hip_xz = 0.5 * (home.xz + other.xz) + sign * 0.06 * left
    out: list[tuple[float, float]] = []
    cursor = start + p["shift"]
    cur = home
    for _ in range(p["count"]):
        t0, t1 = cursor, cursor + p["kick"]
        k = p["kick"]
        if p["kind"] == "front":
            apex = hip_xz + fwd * reach
            chamber = home.xz + fwd * 0.22
            tilt = -0.7
        else:
            apex = hip_xz + sign * left * reach + fwd * 0.05
            chamber = home.xz + sign * left * 0.12 + fwd * 0.12
            tilt = -0.3
        cy = ANKLE_HEIGHT + 0.55 * h
        keys_t = np.array([t0 + 0.3 * k, t0 + 0.5 * k, t0 + 0.7 * k])
        keys_p = np.array(
            [[chamber[0], cy, chamber[1]], [apex[0], h, apex[1]], [chamber[0], cy - 0.05, chamber[1]]]
        )
        cur.t_off = t0
        cur.lift_pitch = -0.4
        cur.lift_time = 0.15
        nxt = Stance(t1, np.inf, home.xz.copy(), home.yaw, land_pitch=-0.15, land_time=0.1)
        nxt.swing_keys = (keys_t, keys_p, np.array([-0.35, tilt, -0.3]))
        stances[leg].append(nxt)
        cur = nxt
        out.append((t0, t1))
        cursor = t1 + p["between"]
    return out


def kick_body(plan: BodyPlan, p: dict, t: np.ndarray, start: float, kicks: list[tuple[float, float]]) -> None:
    """Weight over the standing leg, lean back (front kick) or away (side kick), fists up."""
    n = len(t)
    leg = p["leg"]
    stance = OTHER[leg]
    end = kicks[-1][1]
    w = window(t, start, end + 0.5, p["shift"], 0.5)
    ext = np.zeros(n)
    for t0, t1 in kicks:
        ext = np.maximum(ext, window(t, t0 + 0.2 * (t1 - t0), t0 + 0.85 * (t1 - t0), 0.3 * (t1 - t0)))
    shift = plan.pelvis_shift.copy() if plan.pelvis_shift is not None else np.zeros((n, 3))
    shift[:, 0] += SIDE_SIGN[stance] * 0.1 * w
    plan.pelvis_shift = shift
    plan.pelvis_roll = plan.get("pelvis_roll") - SIDE_SIGN[stance] * 0.04 * w
    if p["kind"] == "front":
        plan.pelvis_pitch = plan.get("pelvis_pitch") - 0.12 * ext
        plan.spine_pitch = plan.get("spine_pitch") - 0.1 * ext
    else:
        plan.spine_roll = plan.get("spine_roll") + SIDE_SIGN[stance] * 0.35 * ext
        plan.pelvis_roll = plan.get("pelvis_roll") + SIDE_SIGN[stance] * 0.12 * ext
        plan.spine_twist = plan.get("spine_twist") - SIDE_SIGN[leg] * 0.2 * ext
    for side in SIDES:
        set_ik(plan.arms[side], w, target(side, -0.08, -0.1, 0.22, n), pole(side, 0.6, -1.0, -0.2, n))
    plan.reach = 0.999


def _kick_sample(rng: np.random.Generator) -> dict:
    p = sample_kick(rng)
    p["idle"] = _r(rng.uniform(0.3, 0.9))
    p["seconds"] = _r(max(min(p["idle"] + kick_time(p) + rng.uniform(0.6, 1.2), 9.8), 2.2))
    return p


def _kick_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    person.stagger = 0.0
    feet0 = person.initial_feet(np.zeros(2), person.yaw0)
    stances = {s: [Stance(-np.inf, np.inf, feet0[s][0], feet0[s][1])] for s in SIDES}
    kicks = add_kicks(stances, p, p["idle"], person.yaw0, person.stand_height)
    plan = standing_plan(rng, person, t, stances=stances)
    plan.feet = {s: foot_track(s, stances[s], t) for s in SIDES}
    plan.root_xz = np.tile(0.5 * (feet0["left"][0] + feet0["right"][0]), (len(t), 1))
    kick_body(plan, p, t, p["idle"], kicks)
    return finish(plan)


def kick_slots(p: dict) -> dict[str, Slot]:
    """Fillers for kicks: the leg, the kind and the count (each with its claim)."""
    leg = p["leg"]
    if p["kind"] == "front":
        kind = Slot(("forward", "to the front", "straight ahead"), ("out in front",), ("kick", "front"))
    else:
        kind = Slot(("to the side", "sideways"), ("out to the side",), ("kick", "side"))
    return {
        "leg": Slot((f"{leg} leg", f"{leg} foot"), (), ("leg", leg)),
        "kind": kind,
        "times": times_slot(p["count"]),
        "kicks": counted_slot(p["count"], "kick", "kicks"),
    }


KICK_TEMPLATES = (
    Template("{subj} kicks {kind} with {poss} {leg}"),
    Template("{subj} kicks {kind} {times} with {poss} {leg}"),
    Template("{subj} does {kicks} {kind} using {poss} {leg}"),
    Template("{subj} lifts {poss} {leg} and kicks {kind}"),
    Template("{subj} kicks {times} with the {leg}"),
    Template("{subj} throws {kicks} {kind} with {poss} {leg}", held=True),
    Template("balancing on one leg, {subj} kicks {kind} with the {leg}", held=True),
)

FAMILIES.append(
    Family(
        name="kick",
        group="actions",
        sample=_kick_sample,
        build=_kick_build,
        templates=KICK_TEMPLATES,
        slots=kick_slots,
        core=lambda p: {"leg": p["leg"]},  # the count only where the words say it ({times}, {kicks})
    )
)


# stretch the arms out to the sides ------------------------------------------------------


def _stretch_sample(rng: np.random.Generator) -> dict:
    p = gesture_timing(rng, rng.uniform(0.8, 2.6))
    p.update({"height": _r(rng.uniform(-0.04, 0.12)), "forward": _r(rng.uniform(-0.04, 0.08))})
    return p


def _stretch_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    t = times(frames_for(p["seconds"]))
    n = len(t)
    plan = standing_plan(rng, Person.sample(rng), t)
    w, _, _ = gesture_window(p, t)
    for side in SIDES:
        sign = SIDE_SIGN[side]
        set_ik(
            plan.arms[side],
            w,
            target(side, 0.515, p["height"], p["forward"], n),
            pole(side, 0.2, -0.2, -1.0, n),
            elevation=np.full(n, 0.1),
            arc=(sign * 0.12, -0.05, 0.05),
        )
    plan.spine_pitch = plan.get("spine_pitch") - 0.06 * w
    plan.head_pitch = plan.get("head_pitch") - 0.08 * w
    return finish(plan)


STRETCH = Slot(("stretches", "extends", "spreads"), ("opens",))
FAMILIES.append(
    Family(
        name="stretch_arms",
        group="actions",
        sample=_stretch_sample,
        build=_stretch_build,
        templates=(
            Template("{subj} {stretch} both arms out to the sides"),
            Template("{subj} {stretch} {poss} arms out wide"),
            Template("{subj} holds both arms straight out to the sides"),
            Template("{subj} raises {poss} arms sideways to shoulder height"),
            Template("{subj} {stretch} {poss} arms out like a t"),
            Template("{subj} spreads {poss} arms wide like wings", held=True),
            Template("{subj} makes a t shape with {poss} arms out to the sides", held=True),
        ),
        slots=lambda p: {"stretch": STRETCH},
        core=lambda p: {"hand": "both"},
    )
)


# push with both hands -------------------------------------------------------------------


def _push_sample(rng: np.random.Generator) -> dict:
    p = gesture_timing(rng, rng.uniform(0.6, 1.8))
    p.update(
        {
            "stance": str(rng.choice(["step", "square"])),
            "lead": str(rng.choice(SIDES)),
            "step": _r(rng.uniform(0.3, 0.45)),
            "lean": _r(rng.uniform(0.12, 0.3)),
            "height": _r(rng.uniform(-0.12, 0.0)),
        }
    )
    return p


def _push_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    t = times(frames_for(p["seconds"]))
    n = len(t)
    person = Person.sample(rng)
    person.stagger = 0.0
    stances = None
    if p["stance"] == "step":
        fwd, _ = axes(person.yaw0)
        feet0 = person.initial_feet(np.zeros(2), person.yaw0)
        lead, t_step = p["lead"], max(p["idle"] - 0.1, 0.05)
        stances = {s: [Stance(-np.inf, np.inf, feet0[s][0], feet0[s][1])] for s in SIDES}
        stances[lead][0].t_off = t_step
        stances[lead][0].lift_pitch = -0.3
        stances[lead].append(
            Stance(t_step + 0.45, np.inf, feet0[lead][0] + fwd * p["step"], feet0[lead][1], land_pitch=0.2)
        )
    plan = standing_plan(rng, person, t, stances=stances)
    if stances is not None:
        plan.feet = {s: foot_track(s, stances[s], t) for s in SIDES}
    w, a, b = gesture_window(p, t)
    ext = window(t, a - 0.1, b + 0.1, 0.35, 0.35)
    for side in SIDES:
        guard = target(side, -0.03, p["height"] - 0.15, 0.22, n)
        shove = target(side, -0.05, p["height"], 0.5, n)
        set_ik(plan.arms[side], w, guard + ext[:, None] * (shove - guard), pole(side, 0.5, -1.0, -0.2, n))
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.4 * p["lean"] * w
    plan.spine_pitch = plan.get("spine_pitch") + 0.6 * p["lean"] * w
    shift = plan.get_shift()
    shift[:, 2] += 0.06 * ext
    plan.pelvis_shift = shift
    return finish(plan)


PUSH = Slot(("pushes", "shoves", "is pushing"), ("presses",))
THING = Slot(("something", "a heavy object", "a door", "a wall"), ("a large box",))
FAMILIES.append(
    Family(
        name="push",
        group="actions",
        sample=_push_sample,
        build=_push_build,
        templates=(
            Template("{subj} {push} {thing} with both hands"),
            Template("{subj} {push} forward with both hands"),
            Template("{subj} puts both hands out and {push} {thing}"),
            Template("{subj} leans in and {push} {thing} away with both hands"),
            Template("{subj} {push} {thing} with both palms"),
            Template("using both hands, {subj} {push} against {thing}", held=True),
            Template("{subj} thrusts both arms forward to push {thing}", held=True),
        ),
        slots=lambda p: {"push": PUSH, "thing": THING},
        core=lambda p: {"hand": "both"},
    )
)


# look around ----------------------------------------------------------------------------


def _look_sample(rng: np.random.Generator) -> dict:
    look = str(rng.choice(["both", "left", "right"], p=[0.5, 0.25, 0.25]))
    first = str(rng.choice(SIDES)) if look == "both" else look
    turns = [first, OTHER[first]] if look == "both" else [first]
    if look == "both" and rng.random() < 0.3:
        turns.append(first)
    glances: list[dict] = [
        {
            "side": s,
            "angle": _r(rng.uniform(50.0, 80.0)),
            "turn": _r(rng.uniform(0.5, 0.9)),
            "hold": _r(rng.uniform(0.3, 1.0)),
        }
        for s in turns
    ]
    idle = rng.uniform(0.3, 1.0)
    back = rng.uniform(0.5, 0.9)
    seconds = idle + sum(g["turn"] + g["hold"] for g in glances) + back + rng.uniform(0.3, 0.8)
    return {
        "look": look,
        "glances": glances,
        "idle": _r(idle),
        "back": _r(back),
        "seconds": _r(max(min(seconds, 9.8), 2.2)),
    }


def _look_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    t = times(frames_for(p["seconds"]))
    plan = standing_plan(rng, Person.sample(rng), t)
    kt, kv = [p["idle"]], [0.0]
    for g in p["glances"]:
        angle = SIDE_SIGN[g["side"]] * np.radians(g["angle"])
        kt += [kt[-1] + g["turn"], kt[-1] + g["turn"] + g["hold"]]
        kv += [angle, angle]
    kt.append(kt[-1] + p["back"])
    kv.append(0.0)
    look = keyframes(t, kt, kv)
    plan.head_yaw = plan.get("head_yaw") * 0.3 + 0.8 * look
    plan.spine_twist = plan.get("spine_twist") + 0.25 * look
    plan.pelvis_twist = plan.get("pelvis_twist") + 0.05 * look
    return finish(plan)


def _look_slots(p: dict) -> dict[str, Slot]:
    if p["look"] == "both":
        order = p["glances"][0]["side"]
        other = OTHER[order]
        how = Slot(
            ("around", "left and right", "from side to side", f"to the {order} and then to the {other}"),
            ("all around", f"first {order}, then {other}"),
            ("look", "both"),
        )
    else:
        s = p["look"]
        how = Slot(
            (f"to the {s}", f"to {{poss}} {s}", f"over {{poss}} {s} shoulder"),
            (f"towards the {s} side",),
            ("look", s),
        )
    return {"how": how}


FAMILIES.append(
    Family(
        name="look_around",
        group="actions",
        sample=_look_sample,
        build=_look_build,
        templates=(
            Template("{subj} looks {how}"),
            Template("{subj} turns {poss} head {how}"),
            Template("standing still, {subj} looks {how}"),
            Template("{subj} glances {how}"),
            Template("{subj} stands in place and looks {how}"),
            Template("{subj} peers {how} without moving {poss} feet", held=True),
            Template("keeping {poss} body still, {subj} turns {poss} head {how}", held=True),
        ),
        slots=_look_slots,
        core=lambda p: {},
    )
)


# point ----------------------------------------------------------------------------------


def _point_sample(rng: np.random.Generator) -> dict:
    p = gesture_timing(rng, rng.uniform(0.8, 2.4))
    hand = str(rng.choice(SIDES))
    p.update(
        {
            "hand": hand,
            "where": str(rng.choice(["ahead", hand], p=[0.6, 0.4])),
            "elevation": _r(rng.uniform(-0.15, 0.45)),
            "spread": _r(rng.uniform(-0.2, 0.2)),
        }
    )
    return p


def _point_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    t = times(frames_for(p["seconds"]))
    n = len(t)
    plan = standing_plan(rng, Person.sample(rng), t)
    w, _, _ = gesture_window(p, t)
    side = p["hand"]
    sign = SIDE_SIGN[side]
    e = p["elevation"]
    if p["where"] == "ahead":
        d = np.array([sign * (0.12 + 0.3 * p["spread"]) * np.cos(e), np.sin(e), np.cos(e)])
        look = -sign * 0.1
    else:
        d = np.array([sign * np.cos(e), np.sin(e), 0.25 + 0.2 * p["spread"]])
        look = sign * 0.9
    d = d / np.linalg.norm(d)
    set_ik(
        plan.arms[side],
        w,
        np.tile(0.51 * d, (n, 1)),
        pole(side, 0.3, -1.0, -0.3, n),
        elevation=np.full(n, 0.12),
    )
    plan.head_yaw = plan.get("head_yaw") + look * w
    plan.head_pitch = plan.get("head_pitch") - 0.5 * e * w
    return finish(plan)


def _point_slots(p: dict) -> dict[str, Slot]:
    hand = p["hand"]
    if p["where"] == "ahead":
        where = Slot(
            ("straight ahead", "forward", "at something in front"),
            ("at something ahead",),
            ("where", "ahead"),
        )
    else:
        where = Slot(
            (f"to the {hand}", f"to {{poss}} {hand}", f"at something on {{poss}} {hand}"),
            (f"off to the {hand} side",),
            ("where", hand),
        )
    return {"hand": hand_slot(hand), "where": where}


FAMILIES.append(
    Family(
        name="point",
        group="actions",
        sample=_point_sample,
        build=_point_build,
        templates=(
            Template("{subj} points {where} with {poss} {hand}"),
            Template("{subj} raises {poss} {hand} and points {where}"),
            Template("with {poss} {hand}, {subj} points {where}"),
            Template("{subj} extends {poss} {hand} to point {where}"),
            Template("{subj} points {where} using {poss} {hand}"),
            Template("{subj} shows the way {where} by pointing with {poss} {hand}", held=True),
            Template("{subj} holds out {poss} {hand} pointing {where}", held=True),
        ),
        slots=_point_slots,
        core=lambda p: {"hand": p["hand"]},
    )
)


# carry ----------------------------------------------------------------------------------


def carry_arms(plan: BodyPlan, p: dict, weight: np.ndarray) -> None:
    """Hold both forearms in front (an object at the waist) with ``weight``; no arm swing."""
    n = plan.n
    for side in SIDES:
        tgt = target(side, -0.5 * (0.4 - p["grip"]), p["hold_height"], p["hold_forward"], n)
        set_ik(plan.arms[side], weight, tgt, pole(side, 0.5, -1.0, -0.3, n))
    plan.spine_pitch = plan.get("spine_pitch") - 0.06 * weight


def sample_carry(rng: np.random.Generator) -> dict:
    """How an object is held in front: hand separation, height and reach (m, chest frame)."""
    return {
        "grip": _r(rng.uniform(0.26, 0.42)),
        "hold_height": _r(rng.uniform(-0.34, -0.2)),
        "hold_forward": _r(rng.uniform(0.28, 0.38)),
    }


def _carry_sample(rng: np.random.Generator) -> dict:
    p = _sample_travel(rng, rng.uniform(0.65, 1.2), (1.8, 7.0))
    p.update(sample_carry(rng))
    return p


def _carry_build(p: dict, rng: np.random.Generator) -> np.ndarray:
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    v = p["speed"]
    t_stop = t[-1] - p["tail"] if p["stops"] else t[-1] + 5.0
    speed = v * window(t, p["idle"], t_stop, p["ease"], p["ease"])
    path = RootPath.from_velocity(t, speed, 0.0, np.full(n, person.yaw0), FPS)
    cad = cadence("walk", v)
    gait = Gait(
        cadence=cad,
        duty=walk_duty(v) + 0.02,
        width=person.width,
        step_ref=v / cad,
        toe_out=person.toe_out,
        first=p["first"],
        start=max(p["idle"] - 0.05, 0.0),
    )
    plan = locomotion_plan(rng, person, t, path, gait, Style(kind="walk", bob=0.025, lean=0.0, arm_swing=0.0))
    carry_arms(plan, p, np.ones(n))
    return finish(plan)


HOLD = Slot(("carries", "is carrying", "holds"), ("hauls",))
FAMILIES.append(
    Family(
        name="carry",
        group="actions",
        sample=_carry_sample,
        build=_carry_build,
        templates=(
            Template("{subj} {walk} {forward} carrying a box with both hands"),
            Template("{subj} {hold} something in front of {poss} chest while walking {forward}"),
            Template("{subj} {walk} {forward} holding an object in both arms"),
            Template("{subj} {hold} a box and walks {forward}"),
            Template("holding something in front of {poss} body, {subj} {walk} {forward}"),
            Template("{subj} lugs a heavy box {forward} in both arms", held=True),
            Template("{subj} transports a package while walking {forward}", held=True),
        ),
        slots=lambda p: {"walk": WALK, "forward": FORWARD, "hold": HOLD},
        core=lambda p: {"travel": "forward", "carry": True},
    )
)
