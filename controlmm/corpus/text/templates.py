"""Caption templates with synonym slots, held-out phrasings and claims.

A :class:`Template` is a string with ``{slot}`` fields. Each slot is filled from a
:class:`Slot`: the phrasings seen in training (``options``) and phrasings kept for the test
split only (``held``). A slot may carry a *claim*, the property of the motion its words
state (e.g. ``("hand", "left")``); the probes check exactly the claims of a caption.
Training captions use only training templates and options; every test caption contains at
least one held-out phrasing (a held-out template or a held-out option).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controlmm.corpus.text.pos import tag


@dataclass(frozen=True)
class Slot:
    """Phrasings for one ``{field}``: ``options`` (train) and ``held`` (test only)."""

    options: tuple[str, ...]
    held: tuple[str, ...] = ()
    claim: tuple[str, Any] | None = None


@dataclass(frozen=True)
class Template:
    """A caption pattern; ``held=True`` keeps the whole pattern for the test split."""

    text: str
    held: bool = False

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(re.findall(r"{(\w+)}", self.text))


@dataclass(frozen=True)
class Caption:
    """A caption with its HumanML3D tokens, template id, held-out flag and claims."""

    text: str
    tokens: str
    template: str
    held_out: bool
    claims: dict[str, Any] = field(default_factory=dict)

    def line(self) -> str:
        """The HumanML3D text-file line ``caption#tokens#start#end``."""
        return f"{self.text}#{self.tokens}#0.0#0.0"

    def to_json(self) -> dict[str, Any]:
        return {
            "text": self.text,
            "template": self.template,
            "held_out": self.held_out,
            "claims": self.claims,
        }


SUBJECTS = (
    ("a person", "their"),
    ("someone", "their"),
    ("a man", "his"),
    ("the person", "their"),
    ("a woman", "her"),
    ("a human", "their"),
)
HELD_SUBJECTS = (("an individual", "their"), ("the man", "his"), ("a guy", "his"), ("the woman", "her"))


def render(
    family: str,
    templates: tuple[Template, ...],
    slots: dict[str, Slot],
    rng: np.random.Generator,
    held_out: bool,
    count: int,
    core: dict[str, Any] | None = None,
) -> list[Caption]:
    """Write ``count`` different captions.

    Args:
        family: family name (template ids are ``family/index``).
        templates: the family's patterns.
        slots: fillers for the patterns' fields (``subj`` and ``poss`` are provided here).
        rng: random generator.
        held_out: test-split captions (each contains a held-out phrasing) or training ones
            (none does).
        count: number of captions.
        core: claims every caption makes (added to each caption's claims).
    """
    usable = [(i, tp) for i, tp in enumerate(templates) if held_out or not tp.held]
    out: list[Caption] = []
    seen: set[str] = set()
    for _ in range(count * 40):
        if len(out) == count:
            break
        i, tp = usable[int(rng.integers(len(usable)))]
        cap = _fill(family, i, tp, slots, rng, held_out, core or {})
        if cap is not None and cap.text not in seen:
            seen.add(cap.text)
            out.append(cap)
    if len(out) < count:
        raise RuntimeError(f"family '{family}' cannot make {count} different captions")
    return out


def _fill(
    family: str,
    index: int,
    tp: Template,
    slots: dict[str, Slot],
    rng: np.random.Generator,
    held_out: bool,
    core: dict[str, Any],
) -> Caption | None:
    subjects = SUBJECTS + (HELD_SUBJECTS if held_out else ())
    subj_i = int(rng.integers(len(subjects)))
    values: dict[str, str] = {}
    used_held = tp.held or subj_i >= len(SUBJECTS)
    claims = dict(core)
    fields = [f for f in tp.fields if f not in ("subj", "poss")]
    for name in fields:
        if name in values:
            continue
        slot = slots[name]
        pool = list(slot.options) + (list(slot.held) if held_out else [])
        k = int(rng.integers(len(pool)))
        values[name] = pool[k]
        used_held = used_held or k >= len(slot.options)
        if slot.claim is not None:
            key, value = slot.claim
            if claims.get(key, value) != value:
                raise ValueError(
                    f"template {family}/{index}: slot '{name}' claims {key}={value!r}, "
                    f"another part claims {claims[key]!r}"
                )
            claims[key] = value
    if held_out and not used_held:
        # Force one held-out phrasing: the subject, or a slot that has held-out options.
        candidates = [f for f in dict.fromkeys(fields) if slots[f].held]
        if candidates and rng.random() < 0.7:
            name = candidates[int(rng.integers(len(candidates)))]
            values[name] = slots[name].held[int(rng.integers(len(slots[name].held)))]
        else:
            subj_i = len(SUBJECTS) + int(rng.integers(len(HELD_SUBJECTS)))
        used_held = True
    if not held_out and used_held:
        return None
    values["subj"], values["poss"] = subjects[subj_i]
    text = tp.text.format(**values).replace("{poss}", values["poss"])
    text = re.sub(r"\s+", " ", text).strip()
    text = re.sub(r"\s+([,.])", r"\1", text)
    text = text[0].lower() + text[1:]
    if not text.endswith("."):
        text += "."
    return Caption(
        text=text, tokens=tag(text), template=f"{family}/{index}", held_out=held_out, claims=claims
    )


def phrase_words(templates: tuple[Template, ...], slots: dict[str, Slot]) -> set[str]:
    """Every word a family can write (for checking the POS lexicon)."""
    texts = [tp.text for tp in templates]
    for slot in slots.values():
        texts += list(slot.options) + list(slot.held)
    texts += [s for s, _ in SUBJECTS + HELD_SUBJECTS] + [p for _, p in SUBJECTS + HELD_SUBJECTS]
    words: set[str] = set()
    for text in texts:
        text = re.sub(r"{\w+}", " ", text)
        words.update(w for w in re.findall(r"[a-z0-9']+", text.lower()))
    return words
