"""A small part-of-speech tagger for the corpus' own captions (no downloads).

HumanML3D stores each caption with its tokens as ``lemma/POS`` pairs (spaCy's universal
tags, lower-cased lemmas, punctuation dropped), e.g. ``a/DET person/NOUN walk/VERB
forward/ADV``. Captions here come from a closed vocabulary, so a lexicon plus a few
context rules for ambiguous words ("left", "right", "back", "around", "up") is enough.
Unknown words raise an error: the tests check that every word a family can write is known.
"""

from __future__ import annotations

import re

from controlmm.errors import ControlMMError

# Verbs: lemma -> inflected forms used in captions.
_VERBS = {
    "walk": "walks walking walk",
    "move": "moves moving",
    "step": "steps stepping step",
    "stride": "strides",
    "proceed": "proceeds",
    "jog": "jogs jogging jog",
    "run": "runs running run",
    "sprint": "sprints",
    "dash": "dashes",
    "race": "races",
    "trot": "trots",
    "do": "does",
    "break": "breaks",
    "take": "takes",
    "cover": "covers",
    "go": "goes go",
    "back": "backs",
    "retreat": "retreats",
    "sidestep": "sidesteps",
    "shuffle": "shuffles",
    "slide": "slides",
    "crouch": "crouches crouching",
    "sneak": "sneaks",
    "stay": "staying stays",
    "keep": "keeping keeps",
    "creep": "creeps",
    "squat": "squats squatting",
    "stop": "stops stopping",
    "pause": "pauses",
    "continue": "continues",
    "come": "comes",
    "halt": "halts",
    "resume": "resumes",
    "head": "heads",
    "stand": "stands standing",
    "make": "makes",
    "approach": "approaches",
    "turn": "turns turning",
    "pivot": "pivots",
    "rotate": "rotates",
    "circle": "circles",
    "curve": "curves curved",
    "bend": "bending bends bent",
    "follow": "follows",
    "veer": "veers",
    "drift": "drifts",
    "zigzag": "zigzags zigzagging",
    "weave": "weaving",
    "change": "changing",
    "jump": "jumps",
    "hop": "hops",
    "leap": "leaps",
    "bound": "bounds",
    "perform": "performs",
    "complete": "completes",
    "lower": "lowers",
    "kneel": "kneels kneeling",
    "drop": "drops",
    "get": "gets get",
    "rest": "resting rests rest",
    "sink": "sinks",
    "rise": "rises rising",
    "remain": "remains",
    "wave": "waves waving",
    "flap": "flaps",
    "raise": "raises raised",
    "lift": "lifts lift",
    "put": "puts",
    "hoist": "hoists",
    "stretch": "stretches stretching",
    "ask": "asking",
    "throw": "throws",
    "reach": "reaches reaching",
    "extend": "extends",
    "grab": "grab grabs",
    "lean": "leans",
    "try": "tries",
    "touch": "touch",
    "punch": "punches",
    "box": "boxes",
    "hit": "hitting",
    "jab": "jabs",
    "strike": "strikes",
    "land": "lands",
    "clap": "claps clapping",
    "give": "gives",
    "applaud": "applauds",
    "bring": "brings",
    "smack": "smacks",
    "greet": "greets",
    "face": "faces facing",
    "begin": "begins",
    "set": "sets",
    "spin": "spins",
    "start": "starts",
    "stroll": "strolls",
    "sit": "sits sitting sit",
    "settle": "settles",
    "lie": "lies lying lie",
    "bow": "bows bowing",
    "pick": "picks pick picking",
    "collect": "collect collects",
    "stoop": "stoops",
    "seat": "seated",
    "balance": "balancing",
    "carry": "carries carrying",
    "haul": "hauls",
    "hold": "holds holding",
    "kick": "kicks",
    "look": "looks",
    "glance": "glances",
    "lug": "lugs",
    "open": "opens",
    "peer": "peers",
    "point": "points pointing point",
    "press": "presses",
    "push": "pushes pushing push",
    "shove": "shoves",
    "show": "shows",
    "spread": "spreads",
    "thrust": "thrusts",
    "transport": "transports",
    "ascend": "ascends",
    "clear": "clears",
    "climb": "climbs",
    "cross": "crosses",
    "descend": "descends",
    "fall": "fallen",
    "end": "ends",
}
_AUX = {"is": "be"}
_WORDS: dict[str, tuple[str, ...]] = {
    "DET": ("a", "an", "the", "both", "some", "several", "few", "his", "her", "their", "each", "all"),
    "PRON": ("someone", "something", "it", "them"),
    "NOUN": (
        "person",
        "man",
        "woman",
        "human",
        "individual",
        "guy",
        "hand",
        "hands",
        "arm",
        "arms",
        "knee",
        "knees",
        "head",
        "body",
        "side",
        "spot",
        "place",
        "point",
        "location",
        "mark",
        "meters",
        "m",
        "pace",
        "line",
        "circle",
        "loop",
        "path",
        "route",
        "pattern",
        "arc",
        "curve",
        "zig",
        "zag",
        "zigzag",
        "direction",
        "clock",
        "degree",
        "degrees",
        "turn",
        "turnaround",
        "u",
        "angle",
        "quarter",
        "quarters",
        "jump",
        "jumps",
        "hop",
        "hops",
        "squat",
        "squats",
        "punch",
        "punches",
        "clap",
        "claps",
        "fist",
        "fists",
        "palms",
        "chest",
        "air",
        "ceiling",
        "sky",
        "shelf",
        "object",
        "question",
        "celebration",
        "stance",
        "position",
        "ground",
        "feet",
        "toes",
        "tiptoes",
        "crouch",
        "walk",
        "run",
        "moment",
        "pause",
        "speed",
        "way",
        "time",
        "times",
        "middle",
        "goodbye",
        "hello",
        "ninety",
        "steps",
        "reverse",
        "spin",
        "stop",
        "halt",
        "audience",
        "bench",
        "bow",
        "bows",
        "box",
        "chair",
        "face",
        "floor",
        "item",
        "seat",
        "stool",
        "waist",
        "door",
        "foot",
        "height",
        "kick",
        "kicks",
        "leg",
        "package",
        "shape",
        "shoulder",
        "sides",
        "t",
        "wall",
        "wings",
        "barrier",
        "flight",
        "hurdle",
        "legs",
        "log",
        "obstacle",
        "platform",
        "stage",
        "staircase",
        "stairs",
        "step",
    ),
    "ADJ": (
        "slow",
        "fast",
        "normal",
        "steady",
        "regular",
        "moderate",
        "gentle",
        "easy",
        "light",
        "full",
        "complete",
        "half",
        "straight",
        "deep",
        "small",
        "short",
        "single",
        "wide",
        "long",
        "high",
        "low",
        "same",
        "round",
        "fighting",
        "possible",
        "still",
        "clockwise",
        "counterclockwise",
        "anticlockwise",
        "counter",
        "front",
        "sideways",
        "flat",
        "upper",
        "heavy",
        "large",
        "first",
        "other",
        "raised",
        "fallen",
    ),
    "ADV": (
        "forward",
        "forwards",
        "ahead",
        "backward",
        "backwards",
        "rearward",
        "onward",
        "sideways",
        "leftward",
        "rightward",
        "upward",
        "slowly",
        "quickly",
        "briskly",
        "leisurely",
        "unhurriedly",
        "hurriedly",
        "rapidly",
        "carefully",
        "gradually",
        "briefly",
        "always",
        "again",
        "then",
        "once",
        "twice",
        "directly",
        "diagonally",
        "roughly",
        "about",
        "around",
        "away",
        "overhead",
        "there",
        "down",
        "up",
        "out",
        "back",
        "on",
        "off",
        "together",
        "high",
        "as",
        "fast",
        "straight",
        "not",
        "along",
        "clockwise",
        "counterclockwise",
        "anticlockwise",
        "flat",
        "politely",
        "first",
    ),
    "ADP": (
        "to",
        "in",
        "with",
        "by",
        "for",
        "from",
        "into",
        "onto",
        "of",
        "at",
        "on",
        "over",
        "above",
        "after",
        "before",
        "toward",
        "towards",
        "without",
        "against",
        "like",
        "using",
        "along",
    ),
    "CCONJ": ("and", "or"),
    "SCONJ": ("while", "if", "as"),
    "NUM": ("one", "two", "three", "four", "five", "six", "ninety", "hundred", "seventy", "eighty"),
    "PART": ("to", "not"),
}

_PLURAL_LEMMA = {
    "hands": "hand",
    "arms": "arm",
    "knees": "knee",
    "meters": "meter",
    "m": "meter",
    "degrees": "degree",
    "jumps": "jump",
    "hops": "hop",
    "squats": "squat",
    "punches": "punch",
    "claps": "clap",
    "fists": "fist",
    "palms": "palm",
    "feet": "foot",
    "toes": "toe",
    "tiptoes": "tiptoe",
    "times": "time",
    "steps": "step",
    "quarters": "quarter",
    "forwards": "forward",
    "backwards": "backward",
    "towards": "toward",
    "an": "a",
    "bows": "bow",
    "kicks": "kick",
    "sides": "side",
    "wings": "wing",
    "legs": "leg",
    "stairs": "stair",
}

LEXICON: dict[str, list[tuple[str, str]]] = {}
"""word -> possible (lemma, POS) readings."""
for _pos, _words in _WORDS.items():
    for _w in _words:
        LEXICON.setdefault(_w, []).append((_PLURAL_LEMMA.get(_w, _w), _pos))
for _lemma, _forms in _VERBS.items():
    for _w in _forms.split():
        LEXICON.setdefault(_w, []).append((_lemma, "VERB"))
for _w, _lemma in _AUX.items():
    LEXICON.setdefault(_w, []).append((_lemma, "AUX"))

_SUBJECTS = {"person", "man", "woman", "human", "individual", "guy", "someone", "and", "then", "is"}
_MODIFIERS = (
    set(_WORDS["DET"]) | set(_WORDS["NUM"]) | set(_WORDS["ADJ"]) - {"sideways", "still", "fast", "straight"}
)
_DETS = {"a", "an", "the", "his", "her", "their", "both", "some"}
_BODY = {"hand", "hands", "arm", "arms", "knee", "foot", "leg", "side", "one", "fist", "direction"}
_OWNERS = {"the", "his", "her", "their", "a", "front"}
_DEFAULT_ORDER = ("VERB", "AUX", "ADV", "ADP", "SCONJ", "CCONJ", "PART", "ADJ", "NUM", "DET", "PRON", "NOUN")


def tokenize(text: str) -> list[str]:
    """Lower-cased word tokens; punctuation dropped, hyphenated words split."""
    return re.findall(r"[a-z0-9]+", text.lower())


def _pick(options: list[tuple[str, str]], *prefer: str) -> tuple[str, str] | None:
    for pos in prefer:
        for opt in options:
            if opt[1] == pos:
                return opt
    return None


def _tag_word(words: list[str], i: int) -> tuple[str, str]:
    w = words[i]
    nxt = words[i + 1] if i + 1 < len(words) else ""
    prev = words[i - 1] if i > 0 else ""
    if w.isdigit():
        return w, "NUM"
    if w in ("left", "right"):
        if nxt in _BODY:
            return w, "ADJ"
        return (w, "NOUN") if prev in _OWNERS else (w, "ADV")
    if w not in LEXICON:
        raise ControlMMError(f"the caption tagger does not know the word '{w}'")
    options = LEXICON[w]
    if len(options) == 1:
        return options[0]
    if (nxt in _DETS or nxt in _WORDS["NUM"] or nxt.isdigit()) and (choice := _pick(options, "ADP")):
        return choice
    if w == "to" and nxt in LEXICON and any(pos == "VERB" for _, pos in LEXICON[nxt]):
        return "to", "PART"
    if prev == "to" and (choice := _pick(options, "VERB")):
        return choice
    if prev in _SUBJECTS and (choice := _pick(options, "VERB")):
        return choice
    if w == "front" and prev == "in":
        return "front", "NOUN"
    if w == "straight" and nxt in ("ahead", "forward", "forwards", "up", "on"):
        return "straight", "ADV"
    noun_before = prev in LEXICON and all(pos == "NOUN" for _, pos in LEXICON[prev]) and prev not in _SUBJECTS
    if (prev in _MODIFIERS or noun_before) and (choice := _pick(options, "NOUN", "ADJ")):
        return choice
    if w == "as" and nxt == "fast":
        return "as", "ADV"
    return _pick(options, *_DEFAULT_ORDER) or options[0]


def tag(text: str) -> str:
    """HumanML3D token string ``lemma/POS lemma/POS ...`` of a caption."""
    words = tokenize(text)
    return " ".join(f"{lemma}/{pos}" for lemma, pos in (_tag_word(words, i) for i in range(len(words))))
