"""Shared phrasings for captions: verbs, speeds, directions, hands, counts and angles.

Each function returns a :class:`Slot` (training options, held-out options, claim).
"""

from __future__ import annotations

from controlmm.corpus.text.templates import Slot

NUMBER_WORDS = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six"}
TIMES_WORDS = {
    1: ("once", "one time"),
    2: ("twice", "two times"),
    3: ("three times",),
    4: ("four times",),
    5: ("five times",),
    6: ("six times",),
}


def times_slot(n: int, key: str = "count") -> Slot:
    """'twice', 'three times' (held out: '3 times')."""
    held = ("a single time",) if n == 1 else (f"{n} times",)
    return Slot(TIMES_WORDS[n], held, (key, n))


def counted_slot(n: int, noun: str, plural: str, key: str = "count") -> Slot:
    """'two jumps' (held out: '2 jumps')."""
    word = noun if n == 1 else plural
    options = (f"{NUMBER_WORDS[n]} {word}",) + (("a single " + noun,) if n == 1 else ())
    return Slot(options, (f"{n} {word}",), (key, n))


WALK = Slot(("walks", "is walking", "moves", "is moving", "steps"), ("strides", "proceeds"))
JOG = Slot(("jogs", "is jogging", "runs slowly", "jogs along"), ("trots", "does a light run"))
RUN = Slot(("runs", "is running", "sprints"), ("dashes", "races"))

FORWARD = Slot(
    ("forward", "forwards", "straight ahead", "ahead", "straight forward"),
    ("onward", "straight on"),
    ("travel", "forward"),
)
BACKWARD = Slot(
    ("backward", "backwards", "in reverse"), ("in a backward direction", "rearward"), ("travel", "backward")
)


def speed_slot(cls: str) -> Slot:
    """Speed adverbs for 'slow', 'normal' or 'fast' walking."""
    if cls == "slow":
        return Slot(
            ("slowly", "at a slow pace", "leisurely"), ("unhurriedly", "at a gentle pace"), ("speed", "slow")
        )
    if cls == "fast":
        return Slot(
            ("quickly", "fast", "briskly", "at a fast pace"), ("hurriedly", "rapidly"), ("speed", "fast")
        )
    return Slot(
        ("", "at a normal pace", "at a steady pace"),
        ("at a regular pace", "at a moderate pace"),
        ("speed", "normal"),
    )


def side_slot(side: str, key: str = "direction") -> Slot:
    """'to the left', 'to their left', 'leftward' (held out: 'towards the left side')."""
    return Slot(
        (f"to the {side}", f"to {{poss}} {side}", f"{side}", f"{side}ward"),
        (f"towards the {side} side", f"in the {side} direction"),
        (key, side),
    )


def hand_slot(side: str, key: str = "hand") -> Slot:
    """'left hand' / 'left arm'."""
    return Slot((f"{side} hand", f"{side} arm"), (), (key, side))
