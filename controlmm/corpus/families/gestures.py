"""Arm gestures while standing: wave, raise one or both arms, clap.

Wrist targets are given relative to the shoulder in the chest frame (x = the person's left,
y up, z forward); ``out`` below means away from the body's midline on the arm's side.
"""

from __future__ import annotations

import numpy as np

from controlmm.corpus.curves import window
from controlmm.corpus.families.base import Person, finish, frames_for, set_ik, standing_plan, times
from controlmm.corpus.family import Family
from controlmm.corpus.rig import SIDE_SIGN
from controlmm.corpus.text.templates import Slot, Template
from controlmm.corpus.text.vocab import counted_slot, hand_slot, times_slot

FAMILIES: list[Family] = []
"""This module's families, in registry order."""

OTHER = {"left": "right", "right": "left"}


def _r(x: float) -> float:
    return float(round(float(x), 4))


def target(side: str, out: float, up: float, fwd: float, n: int) -> np.ndarray:
    """A constant wrist target (n, 3) relative to the shoulder, ``out`` away from the midline."""
    return np.tile(np.array([SIDE_SIGN[side] * out, up, fwd]), (n, 1))


def pole(side: str, out: float, up: float, fwd: float, n: int) -> np.ndarray:
    """Elbow direction (n, 3) in the chest frame."""
    return target(side, out, up, fwd, n)


def gesture_timing(rng: np.random.Generator, action: float) -> dict:
    """Random idle, raise, ``action`` and lower durations of a standing gesture (s)."""
    idle = rng.uniform(0.3, 1.0)
    rise, fall = rng.uniform(0.45, 0.8), rng.uniform(0.5, 0.9)
    tail = rng.uniform(0.3, 1.0)
    return {
        "idle": _r(idle),
        "rise": _r(rise),
        "fall": _r(fall),
        "action": _r(action),
        "seconds": _r(max(min(idle + rise + action + fall + tail, 9.8), 2.2)),
    }


def gesture_window(p: dict, t: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Weight (T,) of a gesture (0 -> 1 -> 0) and the times its full action starts and ends."""
    t_on = p["idle"]
    t_off = t_on + p["rise"] + p["action"] + p["fall"]
    return window(t, t_on, t_off, p["rise"], p["fall"]), t_on + p["rise"], t_off - p["fall"]


# wave -------------------------------------------------------------------------------------


def _wave_sample(rng):
    freq = rng.uniform(1.4, 2.4)
    cycles = int(rng.integers(3, 7))
    p = gesture_timing(rng, cycles / freq)
    p.update(
        {
            "freq": _r(freq),
            "cycles": cycles,
            "amplitude": _r(rng.uniform(0.08, 0.14)),
            "height": _r(rng.uniform(0.36, 0.46)),
        }
    )
    return p


def add_wave(plan, p: dict, side: str, t: np.ndarray, t_shift: float = 0.0) -> None:
    """Raise the ``side`` hand above the head and wave it side to side."""
    n = len(t)
    q = dict(p, idle=p["idle"] + t_shift)
    w, a, b = gesture_window(q, t)
    osc = p["amplitude"] * np.sin(2 * np.pi * p["freq"] * (t - a)) * window(t, a - 0.2, b + 0.2, 0.3)
    tgt = target(side, 0.17, p["height"], 0.1, n)
    tgt[:, 0] += SIDE_SIGN[side] * osc
    set_ik(
        plan.arms[side], w, tgt, pole(side, 1.0, -0.6, -0.3, n), elevation=np.full(n, 0.25), arc=(0, 0, 0.2)
    )
    plan.spine_roll = plan.get("spine_roll") - SIDE_SIGN[side] * 0.05 * w


def _wave_builder(side: str):
    def build(p, rng):
        t = times(frames_for(p["seconds"]))
        plan = standing_plan(rng, Person.sample(rng), t)
        add_wave(plan, p, side, t)
        return finish(plan)

    return build


WAVE_VERB = Slot(("waves", "is waving"), ("flaps",))


def _wave_family(side: str) -> Family:
    return Family(
        name=f"wave_{side}",
        group="gestures",
        sample=_wave_sample,
        build=_wave_builder(side),
        templates=(
            Template("{subj} {wave} {poss} {hand}"),
            Template("{subj} raises {poss} {hand} and waves"),
            Template("{subj} {wave} hello with {poss} {hand}"),
            Template("{subj} lifts {poss} {hand} above {poss} head and {wave} it"),
            Template("{subj} {wave} goodbye using {poss} {hand}"),
            Template("with {poss} {hand} raised, {subj} {wave} to someone", held=True),
            Template("{subj} greets someone by waving {poss} {hand} overhead", held=True),
        ),
        slots=lambda p: {"wave": WAVE_VERB, "hand": hand_slot(side)},
        core=lambda p: {"hand": side},
    )


for _side in ("left", "right"):
    FAMILIES.append(_wave_family(_side))


# raise arms -------------------------------------------------------------------------------


def _raise_sample(rng):
    p = gesture_timing(rng, rng.uniform(0.6, 2.5))
    p["hand"] = str(rng.choice(["left", "right"]))
    return p


def _raise_build(p, rng):
    t = times(frames_for(p["seconds"]))
    plan = standing_plan(rng, Person.sample(rng), t)
    hands = ("left", "right") if p.get("hand", "both") == "both" else (p["hand"],)
    w, _, _ = gesture_window(p, t)
    for side in hands:
        n = len(t)
        set_ik(
            plan.arms[side],
            w,
            target(side, 0.1, 0.5, 0.05, n),
            pole(side, 1.0, 0.0, -0.5, n),
            elevation=np.full(n, 0.3),
            arc=(0, 0, 0.3),
        )
    return finish(plan)


RAISE = Slot(("raises", "lifts", "puts up"), ("hoists",))
FAMILIES.append(
    Family(
        name="raise_arm",
        group="gestures",
        sample=_raise_sample,
        build=_raise_build,
        templates=(
            Template("{subj} {raise} {poss} {hand}"),
            Template("{subj} {raise} {poss} {hand} above {poss} head"),
            Template("{subj} {raise} {poss} {hand} up high and lowers it"),
            Template("{subj} holds {poss} {hand} straight up"),
            Template("{subj} {raise} {poss} {hand} into the air"),
            Template("{subj} stretches {poss} {hand} up toward the ceiling", held=True),
            Template("{subj} puts {poss} {hand} up as if asking a question", held=True),
        ),
        slots=lambda p: {"raise": RAISE, "hand": hand_slot(p["hand"])},
        core=lambda p: {"hand": p["hand"]},
    )
)

FAMILIES.append(
    Family(
        name="raise_both_arms",
        group="gestures",
        sample=lambda rng: dict(gesture_timing(rng, rng.uniform(0.6, 2.5)), hand="both"),
        build=_raise_build,
        templates=(
            Template("{subj} {raise} both arms"),
            Template("{subj} {raise} both hands above {poss} head"),
            Template("{subj} puts both arms up in the air"),
            Template("{subj} {raise} {poss} arms over {poss} head and lowers them"),
            Template("{subj} lifts both hands up high"),
            Template("{subj} throws both arms up in celebration", held=True),
            Template("{subj} reaches both arms toward the sky", held=True),
        ),
        slots=lambda p: {"raise": RAISE},
        core=lambda p: {"hand": "both"},
    )
)


# clap -------------------------------------------------------------------------------------


def _clap_sample(rng):
    count = int(rng.integers(2, 7))
    freq = rng.uniform(1.5, 2.6)
    p = gesture_timing(rng, count / freq + 0.2)
    p.update({"count": count, "freq": _r(freq), "open": _r(rng.uniform(0.28, 0.4))})
    return p


def _clap_build(p, rng):
    t = times(frames_for(p["seconds"]))
    n = len(t)
    plan = standing_plan(rng, Person.sample(rng), t)
    w, a, b = gesture_window(p, t)
    # Hands meet in front of the chest `count` times: the gap closes sharply at each clap.
    clap_t = a + 0.1 + (np.arange(p["count"]) + 0.5) / p["freq"]
    gap = np.full(n, p["open"])
    for tc in clap_t:
        gap = np.minimum(
            gap, 0.03 + (p["open"] - 0.03) * np.clip(np.abs(t - tc) * p["freq"] * 2.2, 0, 1) ** 1.5
        )
    for side in ("left", "right"):
        tgt = target(side, 0.0, -0.12, 0.32, n)
        tgt[:, 0] = SIDE_SIGN[side] * (-0.19 + 0.5 * gap)
        set_ik(plan.arms[side], w, tgt, pole(side, 0.45, -1.0, -0.1, n))
    return finish(plan)


FAMILIES.append(
    Family(
        name="clap",
        group="gestures",
        sample=_clap_sample,
        build=_clap_build,
        templates=(
            Template("{subj} claps {poss} hands {times}"),
            Template("{subj} claps {times}"),
            Template("{subj} gives {claps}"),
            Template("{subj} applauds, clapping {times}"),
            Template("{subj} brings {poss} hands together {times}"),
            Template("{subj} smacks {poss} palms together {times}", held=True),
            Template("{subj} does {claps} in front of {poss} chest", held=True),
        ),
        slots=lambda p: {"times": times_slot(p["count"]), "claps": counted_slot(p["count"], "clap", "claps")},
        core=lambda p: {"count": p["count"]},
    )
)
