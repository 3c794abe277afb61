"""Whole-body postures: sit down on a seat (and stand up), lie down on the floor (and get up),
bow, pick something up from the floor.

Positions are planned in the person's own ground frame (forward and left of the heading, the
feet's midpoint as origin) and turned into the world with :func:`~controlmm.corpus.families.base.axes`.
A seat is a :class:`~controlmm.corpus.scene.Box` returned with the joints.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.corpus.body import BodyPlan
from controlmm.corpus.curves import ramp, smooth_keys, window
from controlmm.corpus.families.base import (
    Person,
    axes,
    finish,
    frames_for,
    set_world_ik,
    standing_plan,
    times,
)
from controlmm.corpus.family import Built, Family
from controlmm.corpus.feet import Stance, foot_track
from controlmm.corpus.rig import HIP_INDEX, KNEE_INDEX, SIDE_SIGN
from controlmm.corpus.scene import Box, Scene
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import counted_slot, times_slot

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

SIDES = ("left", "right")
SEATED_PELVIS = 0.175
"""Height (m) of the pelvis joint above the seat surface when sitting upright."""


def _r(x: float) -> float:
    return float(round(float(x), 4))


def feet_middle(plan: BodyPlan, t_at: float) -> np.ndarray:
    """Midpoint (2,) as (x, z) of both ankles at time ``t_at`` (a frame of the plan's feet)."""
    k = int(np.clip(round(t_at * plan.fps), 0, plan.n - 1))
    return 0.5 * (plan.feet["left"].ankle[k, [0, 2]] + plan.feet["right"].ankle[k, [0, 2]])


# sit down -------------------------------------------------------------------------------

SEATS = {"chair": (0.42, 0.5), "bench": (1.1, 1.6), "stool": (0.32, 0.4)}
"""Seat kinds and their widths (m)."""


def sample_sit(rng: np.random.Generator, stand_up: bool) -> dict:
    """Seat and timing of a sit-down (and stand-up) that starts when the person stands still."""
    seat = str(rng.choice(list(SEATS)))
    return {
        "seat": seat,
        "seat_height": _r(rng.uniform(0.4, 0.55) if seat != "stool" else rng.uniform(0.45, 0.6)),
        "seat_width": _r(rng.uniform(*SEATS[seat])),
        "back": _r(rng.uniform(0.3, 0.37)),
        "edge": _r(rng.uniform(0.13, 0.18)),
        "down": _r(rng.uniform(1.1, 1.7)),
        "hold": _r(rng.uniform(0.9, 2.4) if stand_up else rng.uniform(0.8, 1.6)),
        "up": _r(rng.uniform(1.1, 1.7)),
        "lean": _r(rng.uniform(0.5, 0.75)),
        "hands": str(rng.choice(["thighs", "lap", "sides"])),
        "stand_up": stand_up,
    }


def apply_sit(plan: BodyPlan, p: dict, t: np.ndarray, start: float, person: Person, yaw: float) -> Box:
    """Sit down on a seat behind the feet from ``start`` (the feet stay planted), stay, and stand
    up again if ``p["stand_up"]``; returns the seat (world frame)."""
    n = len(t)
    fwd, left = axes(yaw)
    mid = feet_middle(plan, start)
    root = plan.root_xz[min(int(round(start * plan.fps)), n - 1)]
    seat_y = p["seat_height"] + SEATED_PELVIS
    stand = person.stand_height
    base = (mid - root) @ fwd  # the feet's midpoint ahead of the root
    side = (mid - root) @ left
    back = base - p["back"]
    t0, t1 = start, start + p["down"]
    lean, upright = p["lean"], 0.06
    keys_t = [t0, t0 + 0.35 * p["down"], t0 + 0.7 * p["down"], t1]
    keys_h = [stand, stand - 0.15, seat_y + 0.06, seat_y]
    keys_z = [0.0, 0.25 * back, 0.8 * back, back]
    keys_l = [0.0, lean, 0.7 * lean, upright]
    if p["stand_up"]:
        r0 = t1 + p["hold"]
        keys_t += [r0, r0 + 0.35 * p["up"], r0 + 0.65 * p["up"], r0 + p["up"]]
        keys_h += [seat_y, seat_y + 0.03, stand - 0.12, stand]
        keys_z += [back, 0.85 * back, 0.3 * back, 0.0]
        keys_l += [upright, lean, 0.6 * lean, 0.0]
    height = smooth_keys(t, keys_t, keys_h)
    shift_z = smooth_keys(t, keys_t, keys_z)
    frac = np.clip((stand - height) / (stand - seat_y), 0.0, 1.0)
    plan.pelvis_height = np.where(
        t >= t0, height + (plan.pelvis_height - stand) * (1 - frac), plan.pelvis_height
    )
    shift = plan.pelvis_shift if plan.pelvis_shift is not None else np.zeros((n, 3))
    shift = shift.copy()
    shift[:, 2] += np.where(t >= t0, shift_z, 0.0)
    shift[:, 0] += side * frac
    plan.pelvis_shift = shift
    bend = smooth_keys(t, keys_t, keys_l) * (t >= t0)
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.55 * bend
    plan.spine_pitch = plan.get("spine_pitch") + 0.45 * bend
    plan.head_pitch = plan.get("head_pitch") - 0.2 * bend
    plan.knee_out = 0.3

    # Hands: on the thighs or in the lap while seated, or beside the hips on the seat.
    seated = np.clip((frac - 0.6) / 0.4, 0.0, 1.0)
    joints = finish(plan)
    for s in SIDES:
        sign = SIDE_SIGN[s]
        hip, knee = joints[:, HIP_INDEX[s]], joints[:, KNEE_INDEX[s]]
        if p["hands"] == "thighs":
            world = hip + 0.6 * (knee - hip) + np.array([0.0, 0.07, 0.0])
        elif p["hands"] == "lap":
            world = hip + 0.35 * (knee - hip) + np.array([0.0, 0.08, 0.0]) - sign * 0.07 * _left3(left)
        else:
            world = hip + sign * 0.16 * _left3(left) + np.array([0.0, -0.02, 0.0]) - 0.02 * _left3(fwd)
        pole = np.tile([sign * 0.5, -0.3, -1.0], (n, 1))
        set_world_ik(plan, s, seated, world, pole)

    depth = 0.42
    front = root + fwd * (back + p["edge"]) + left * side
    center = front - fwd * 0.5 * depth
    return Box(
        "seat",
        (float(center[0]), 0.5 * p["seat_height"], float(center[1])),
        (p["seat_width"], p["seat_height"], depth),
        float(yaw),
    )


def _left3(v2: np.ndarray) -> np.ndarray:
    """A ground vector (2,) as (x, z) -> (3,) with y = 0."""
    return np.array([v2[0], 0.0, v2[1]])


def _sit_sample(rng: np.random.Generator) -> dict:
    stand_up = bool(rng.random() < 0.6)
    p = sample_sit(rng, stand_up)
    p["idle"] = _r(rng.uniform(0.3, 1.0))
    total = p["idle"] + p["down"] + p["hold"] + (p["up"] + rng.uniform(0.3, 0.9) if stand_up else 0.2)
    p["seconds"] = _r(min(total, 9.8))
    return p


def _sit_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    plan = standing_plan(rng, person, t)
    seat = apply_sit(plan, p, t, p["idle"], person, person.yaw0)
    return Built(finish(plan), Scene("seat", (seat,), {"seat_height": p["seat_height"], "seat": p["seat"]}))


def seat_slot(p: dict) -> Slot:
    """'a chair', 'the bench', 'a stool' (held out: 'a seat')."""
    kind = p["seat"]
    return Slot((f"a {kind}", f"the {kind}"), ("a seat",))


def rise_slot(stand_up: bool) -> Slot:
    """How a sit or lie-down ends: standing up again or staying down."""
    if stand_up:
        return Slot(
            (" and then stands back up", " and gets up again", ", then rises"),
            (" before standing up again",),
            ("stand_up", True),
        )
    return Slot(("", " and stays seated", " and remains sitting"), (" and rests there",), ("stand_up", False))


FAMILIES.append(
    Family(
        name="sit_down",
        group="postures",
        sample=_sit_sample,
        build=_sit_build,
        templates=(
            Template("{subj} sits down on {seat}{rise}"),
            Template("{subj} lowers {poss} body onto {seat}{rise}"),
            Template("{subj} takes a seat on {seat}{rise}"),
            Template("{subj} sits back on {seat}{rise}"),
            Template("{subj} bends {poss} knees and sits down on {seat}{rise}"),
            Template("{subj} settles into {seat}{rise}", held=True),
            Template("standing in front of {seat}, {subj} sits{rise}", held=True),
        ),
        slots=lambda p: {"seat": seat_slot(p), "rise": rise_slot(p["stand_up"])},
        core=lambda p: {"seated": True},
    )
)


# lie down -------------------------------------------------------------------------------


def _lie_sample(rng: np.random.Generator) -> dict:
    stand_up = bool(rng.random() < 0.6)
    idle = rng.uniform(0.3, 0.8)
    down = rng.uniform(2.4, 3.2)
    hold = rng.uniform(0.6, 1.8) if stand_up else rng.uniform(0.8, 2.0)
    up = rng.uniform(2.6, 3.4) if stand_up else 0.0
    seconds = idle + down + hold + up + (rng.uniform(0.3, 0.7) if stand_up else 0.0)
    return {
        "idle": _r(idle),
        "down": _r(down),
        "hold": _r(hold),
        "up": _r(up),
        "stand_up": stand_up,
        "back": _r(rng.uniform(0.42, 0.5)),
        "reach": _r(rng.uniform(0.58, 0.64)),
        "seconds": _r(min(seconds, 9.8)),
    }


def _lie_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    n = frames_for(p["seconds"])
    t = times(n)
    person = Person.sample(rng)
    yaw = person.yaw0
    fwd, left = axes(yaw)
    feet0 = person.initial_feet(np.zeros(2), yaw)
    stand = person.stand_height
    a = p["idle"]
    d = p["down"]
    sit_t, lie_t = a + 0.5 * d, a + d
    back = p["back"]  # the seated pelvis lies this far behind the standing feet
    legs = back + p["reach"] - 0.02  # the feet slide this far out so the legs lie almost straight
    # Feet: planted while going down, slide out (low swings) as the legs extend, back in to get up.
    stances: dict[str, list[Stance]] = {}
    for side in SIDES:
        base, foot_yaw = feet0[side]
        out = base + fwd * (legs - back)
        lag = 0.08 if side == "left" else 0.0
        st0 = Stance(-np.inf, sit_t + 0.1 + lag, base, foot_yaw)
        st1 = Stance(sit_t + 0.55 + lag, np.inf, out, foot_yaw, clearance=0.06, lift_skew=0.3)
        st1.pitch_keys = [(sit_t + 0.6 + lag, 0.0), (lie_t, 1.05)]
        lst = [st0, st1]
        if p["stand_up"]:
            g0 = lie_t + p["hold"]
            st1.t_off = g0 + 0.35 + lag
            st1.pitch_keys += [(g0 + 0.05, 1.05), (g0 + 0.3 + lag, 0.0)]
            lst.append(Stance(g0 + 0.85 + lag, np.inf, base + fwd * 0.04, foot_yaw, clearance=0.06))
        stances[side] = lst
    plan = standing_plan(rng, person, t, stances=stances)
    plan.feet = {s: foot_track(s, stances[s], t) for s in SIDES}
    plan.root_xz = np.tile(0.5 * (feet0["left"][0] + feet0["right"][0]), (n, 1))
    plan.reach = 0.999
    plan.knee_up = 1.5 * window(
        t,
        a + 0.2 * d,
        t[-1] + 5.0 if not p["stand_up"] else lie_t + p["hold"] + 0.8 * p["up"],
        0.6 * d,
        0.4 * p["up"] + 1e-3,
    )

    # Pelvis and trunk: squat down and back, sit on the floor, recline; the reverse to get up.
    floor_y = 0.1
    kt = [a, a + 0.3 * d, sit_t, sit_t + 0.25 * d, lie_t]
    kh = [stand, stand - 0.4, floor_y + 0.09, floor_y + 0.07, floor_y]
    kz = [0.0, -0.25 * back, -back, -back, -back]
    kl = [0.0, 0.55, 0.35, -0.4, -1.5]
    if p["stand_up"]:
        g0 = lie_t + p["hold"]
        u = p["up"]
        kt += [g0, g0 + 0.3 * u, g0 + 0.5 * u, g0 + 0.75 * u, g0 + u]
        kh += [floor_y, floor_y + 0.07, floor_y + 0.1, stand - 0.42, stand]
        kz += [-back, -back, -0.75 * back, -0.1, 0.0]
        kl += [-1.5, 0.2, 0.75, 0.6, 0.0]
    plan.pelvis_height = smooth_keys(t, kt, kh) + (plan.pelvis_height - stand) * (t < a)
    shift = np.zeros((n, 3))
    shift[:, 2] = smooth_keys(t, kt, kz)
    plan.pelvis_shift = shift
    lean = smooth_keys(t, kt, kl)
    # Reclining is mostly the pelvis rolling back (the hips stay level with it on the floor).
    pelvis_share = np.where(lean < 0.0, 0.9, 0.6)
    plan.pelvis_pitch = plan.get("pelvis_pitch") + pelvis_share * lean
    plan.spine_pitch = plan.get("spine_pitch") + (1.0 - pelvis_share) * lean
    lying = np.clip(-lean / 1.5, 0.0, 1.0)
    # The head follows the trunk down to the floor (chin a little tucked), then leads getting up.
    plan.head_pitch = plan.get("head_pitch") + lying * (0.55 * lean + 0.25) - 0.2 * np.clip(lean, 0.0, None)
    plan.head_yaw = plan.get("head_yaw") * (1.0 - lying)

    # Hands: reach back to the floor beside the hips while sitting down; getting up, they push
    # on the floor, then on the knees.
    for side in SIDES:
        arm = plan.arms[side]
        arm.flex = arm.flex * (1.0 - lying) + lying * 0.05
        arm.abd = arm.abd + 0.15 * lying
    joints = finish(plan)
    on_knees = np.zeros(n)
    support = window(t, a + 0.25 * d, lie_t - 0.1, 0.5, 0.5)
    if p["stand_up"]:
        g0, u = lie_t + p["hold"], p["up"]
        support = np.maximum(support, window(t, g0 + 0.1 * u, g0 + 0.92 * u, 0.3 * u, 0.2 * u))
        on_knees = ramp(t, g0 + 0.38 * u, g0 + 0.55 * u)
    for side in SIDES:
        sign = SIDE_SIGN[side]
        floor = joints[:, HIP_INDEX[side]] + sign * 0.2 * _left3(left) - 0.12 * _left3(fwd)
        floor[:, 1] = 0.08
        knee = joints[:, KNEE_INDEX[side]] + np.array([0.0, 0.06, 0.0]) + 0.04 * _left3(fwd)
        world = floor + on_knees[:, None] * (knee - floor)
        set_world_ik(plan, side, support, world, np.tile([sign * 0.3, 0.2, -1.0], (n, 1)))
    # Settle the body on the floor: while it is down, the lowest trunk or hip joint rests 10 cm
    # above it (the back's and the buttocks' thickness), and the hips never sink below the ankles
    # (sitting on the floor with the knees up, the thighs rise from the hips).
    joints = finish(plan)
    low = joints[:, [0, 1, 2, 3, 6, 9, 12, 13, 14, 15, 16, 17]][..., 1].min(1)
    hips_under = (joints[:, [7, 8], 1].max(1) + 0.02 - joints[:, [1, 2], 1].min(1)).clip(0.0, None)
    down = gaussian_filter1d((joints[:, 0, 1] < 0.4).astype(np.float64), 2.0, mode="nearest")
    lift = np.maximum(0.1 - low, hips_under)
    plan.pelvis_height = plan.pelvis_height + gaussian_filter1d(lift * down, 1.5, mode="nearest")
    return finish(plan)


FAMILIES.append(
    Family(
        name="lie_down",
        group="postures",
        sample=_lie_sample,
        build=_lie_build,
        templates=(
            Template("{subj} lies down on {poss} back{rise}"),
            Template("{subj} gets down and lies flat on the floor{rise}"),
            Template("{subj} sits down on the ground and lies back{rise}"),
            Template("{subj} lies down on the floor{rise}"),
            Template("{subj} lowers {poss} body to the ground and lies down{rise}"),
            Template("{subj} stretches out on the floor, lying face up{rise}", held=True),
            Template("{subj} goes down to lie on the ground{rise}", held=True),
        ),
        slots=lambda p: {"rise": _lie_rise(p["stand_up"])},
        core=lambda p: {"lies": True},
    )
)


def _lie_rise(stand_up: bool) -> Slot:
    if stand_up:
        return Slot(
            (" and then gets back up", " and gets up again", ", then stands up"),
            (" before rising to {poss} feet",),
            ("stand_up", True),
        )
    return Slot(("", " and stays there", " and rests"), (" and remains lying down",), ("stand_up", False))


# bow ------------------------------------------------------------------------------------


def _bow_sample(rng: np.random.Generator) -> dict:
    count = int(rng.choice([1, 2], p=[0.7, 0.3]))
    bows = [
        {
            "depth": _r(rng.uniform(0.6, 1.05)),
            "down": _r(rng.uniform(0.6, 1.0)),
            "hold": _r(rng.uniform(0.2, 0.9)),
            "up": _r(rng.uniform(0.6, 1.0)),
            "rest": _r(rng.uniform(0.3, 0.7)),
        }
        for _ in range(count)
    ]
    idle = rng.uniform(0.3, 1.0)
    seconds = idle + sum(b["down"] + b["hold"] + b["up"] + b["rest"] for b in bows) + rng.uniform(0.2, 0.8)
    return {
        "count": count,
        "bows": bows,
        "idle": _r(idle),
        "arms": str(rng.choice(["sides", "hang", "front"])),
        "seconds": _r(max(min(seconds, 9.8), 2.2)),
    }


def apply_bow(plan: BodyPlan, p: dict, t: np.ndarray, start: float) -> None:
    """Bow ``p["count"]`` times from ``start``: the hips flex, the head follows, the pelvis moves
    back a little for balance."""
    kt, kv = [start], [0.0]
    cursor = start
    for b in p["bows"]:
        kt += [cursor + b["down"], cursor + b["down"] + b["hold"], cursor + b["down"] + b["hold"] + b["up"]]
        kv += [b["depth"], b["depth"], 0.0]
        cursor = kt[-1] + b["rest"]
    bend = smooth_keys(t, kt, kv) * (t >= start)
    plan.pelvis_pitch = plan.get("pelvis_pitch") + 0.65 * bend
    plan.spine_pitch = plan.get("spine_pitch") + 0.35 * bend
    plan.head_pitch = plan.get("head_pitch") + 0.25 * bend
    shift = plan.pelvis_shift.copy() if plan.pelvis_shift is not None else np.zeros((len(t), 3))
    shift[:, 2] -= 0.13 * bend
    plan.pelvis_shift = shift
    plan.pelvis_height = plan.get("pelvis_height") - 0.02 * bend
    for side in SIDES:
        arm = plan.arms[side]
        if p["arms"] == "hang":  # the arms hang down as the trunk bends
            arm.flex = arm.flex + 0.8 * bend
        elif p["arms"] == "front":  # hands folded in front of the belly
            arm.flex = arm.flex + 0.35 + 0.2 * bend
            arm.elbow = arm.elbow + 1.0
            arm.abd = arm.abd - 0.05
            arm.swing = arm.swing * 0.0


def _bow_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    plan = standing_plan(rng, Person.sample(rng), t)
    apply_bow(plan, p, t, p["idle"])
    return finish(plan)


FAMILIES.append(
    Family(
        name="bow",
        group="postures",
        sample=_bow_sample,
        build=_bow_build,
        templates=(
            Template("{subj} bows {times}"),
            Template("{subj} bows forward {times}"),
            Template("{subj} bends at the waist and bows {times}"),
            Template("{subj} takes {bows}"),
            Template("{subj} makes {bows} to the audience"),
            Template("{subj} politely bows {poss} head and upper body {times}", held=True),
            Template("{subj} greets someone with {bows}", held=True),
        ),
        slots=lambda p: {"times": times_slot(p["count"]), "bows": counted_slot(p["count"], "bow", "bows")},
        core=lambda p: {"count": p["count"]},
    )
)


# pick up --------------------------------------------------------------------------------


def sample_pick(rng: np.random.Generator) -> dict:
    """How an object is picked up from the floor: squatting or stooping, which hands, where."""
    style = str(rng.choice(["squat", "stoop"]))
    return {
        "style": style,
        "hand": str(rng.choice(["both", "left", "right"], p=[0.5, 0.25, 0.25])),
        "distance": _r(rng.uniform(0.26, 0.36) if style == "squat" else rng.uniform(0.25, 0.38)),
        "size": _r(rng.uniform(0.1, 0.22)),
        "depth": _r(rng.uniform(0.5, 0.56) if style == "squat" else rng.uniform(0.24, 0.32)),
        "down": _r(rng.uniform(0.9, 1.4)),
        "grab": _r(rng.uniform(0.3, 0.7)),
        "up": _r(rng.uniform(0.9, 1.4)),
    }


def apply_pick(plan: BodyPlan, p: dict, t: np.ndarray, start: float, person: Person, yaw: float) -> Box:
    """Go down (squat or stoop) from ``start``, take an object from the floor in front of the
    feet and come up holding it in front of the waist until the end; returns the object."""
    n = len(t)
    fwd, left = axes(yaw)
    mid = feet_middle(plan, start)
    stand = person.stand_height
    t1 = start + p["down"]
    t2 = t1 + p["grab"]
    t3 = t2 + p["up"]
    squat = p["style"] == "squat"
    bend_max = 0.95 if squat else 1.6
    keys_t = [start, t1, t2, t3]
    height = smooth_keys(t, keys_t, [stand, stand - p["depth"], stand - p["depth"], stand])
    bend = smooth_keys(t, keys_t, [0.0, bend_max, bend_max, 0.05]) * (t >= start)
    frac = np.clip((stand - height) / p["depth"], 0.0, 1.0)
    plan.pelvis_height = np.minimum(plan.get("pelvis_height"), np.where(t >= start, height, np.inf))
    shift = plan.pelvis_shift.copy() if plan.pelvis_shift is not None else np.zeros((n, 3))
    shift[:, 2] -= (0.2 if squat else 0.16) * np.maximum(frac, bend / bend_max)
    plan.pelvis_shift = shift
    plan.pelvis_pitch = plan.get("pelvis_pitch") + (0.55 if squat else 0.7) * bend
    plan.spine_pitch = plan.get("spine_pitch") + (0.45 if squat else 0.3) * bend
    plan.head_pitch = plan.get("head_pitch") - 0.1 * bend
    plan.knee_out = 0.35 if squat else 0.2

    obj_xz = mid + fwd * p["distance"]
    size = p["size"]
    hands = SIDES if p["hand"] == "both" else (p["hand"],)
    reach = window(t, start + 0.2 * p["down"], t3 + 5.0, 0.8 * p["down"], 0.1)
    held = np.clip((t - t2) / p["up"], 0.0, 1.0)
    pelvis = finish(plan)[:, 0]
    for s in hands:
        sign = SIDE_SIGN[s]
        grip = 0.5 * size + 0.02 if len(hands) == 2 else 0.0
        on_floor = np.array([obj_xz[0], size + 0.05, obj_xz[1]]) + sign * grip * _left3(left)
        # Carried: in front of the belly, a hand's width either side of the object.
        carry = pelvis + 0.33 * _left3(fwd) + np.array([0.0, 0.12, 0.0]) + sign * (grip + 0.05) * _left3(left)
        world = (1.0 - held[:, None]) * on_floor + held[:, None] * carry
        set_world_ik(plan, s, reach, world, np.tile([sign * 0.6, -0.6, -0.6], (n, 1)))
    center = (obj_xz[0], 0.5 * size, obj_xz[1])
    return Box("object", center, (size, size, size), float(yaw))


def _pick_sample(rng: np.random.Generator) -> dict:
    p = sample_pick(rng)
    p["idle"] = _r(rng.uniform(0.3, 1.0))
    p["seconds"] = _r(min(p["idle"] + p["down"] + p["grab"] + p["up"] + rng.uniform(0.4, 1.2), 9.8))
    return p


def _pick_build(p: dict, rng: np.random.Generator) -> np.ndarray | Built:
    t = times(frames_for(p["seconds"]))
    person = Person.sample(rng)
    if p["style"] == "squat":
        person.width = rng.uniform(0.26, 0.36)
        person.toe_out = rng.uniform(0.12, 0.3)
    plan = standing_plan(rng, person, t)
    obj = apply_pick(plan, p, t, p["idle"], person, person.yaw0)
    return Built(finish(plan), Scene("object", (obj,), {"object_size": p["size"]}))


def pick_slots(p: dict) -> dict[str, Slot]:
    """Fillers for picking up: the way down (claims the style) and the hands."""
    if p["style"] == "squat":
        how = Slot(
            ("squats down", "crouches down", "bends {poss} knees"),
            ("drops into a squat",),
            ("style", "squat"),
        )
    else:
        how = Slot(
            ("bends over", "bends forward at the waist", "stoops down"), ("leans down",), ("style", "stoop")
        )
    hands = {"both": "both hands", "left": "{poss} left hand", "right": "{poss} right hand"}[p["hand"]]
    return {
        "how": how,
        "hands": Slot((hands,)),
        "thing": Slot(("something", "an object", "a box"), ("an item",)),
    }


FAMILIES.append(
    Family(
        name="pick_up",
        group="postures",
        sample=_pick_sample,
        build=_pick_build,
        templates=(
            Template("{subj} {how} and picks up {thing} from the floor"),
            Template("{subj} {how} to pick {thing} up off the ground"),
            Template("{subj} {how}, grabs {thing} with {hands} and stands up"),
            Template("{subj} {how} and lifts {thing} from the floor with {hands}"),
            Template("{subj} picks up {thing} from the ground"),
            Template("{subj} {how} to collect {thing} lying at {poss} feet", held=True),
            Template("reaching down to the floor, {subj} {how} and takes {thing}", held=True),
        ),
        slots=pick_slots,
        core=lambda p: {"picks_up": True},
    )
)
