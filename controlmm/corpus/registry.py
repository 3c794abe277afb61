"""The motion-family registry: every family by name.

A family knows how to draw random parameters, build the motion for them, and describe it
(caption templates, slot fillers and the claims its words make). Family modules register
themselves on import (:mod:`controlmm.corpus.families`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from controlmm.corpus.text.templates import Caption, Slot, Template, render
from controlmm.errors import ControlMMError

Params = dict[str, Any]


@dataclass(frozen=True)
class Family:
    """A kind of motion.

    Attributes:
        name: registry name (also the probe's name).
        group: family module ("walking", "turning", "jumping", "lowering", "gestures", "combos").
        sample: rng -> JSON-serialisable parameters (speed, direction, hand, count...).
        build: (params, rng) -> joints (T + 1, 22, 3), metres, Y up; T in 40..196.
        templates: caption patterns.
        slots: params -> fillers of the patterns' fields (with claims).
        core: params -> claims every caption of the family makes.
    """

    name: str
    group: str
    sample: Callable[[np.random.Generator], Params]
    build: Callable[[Params, np.random.Generator], np.ndarray]
    templates: tuple[Template, ...]
    slots: Callable[[Params], dict[str, Slot]]
    core: Callable[[Params], dict[str, Any]] = lambda p: {}

    def captions(
        self, params: Params, rng: np.random.Generator, held_out: bool, count: int = 3
    ) -> list[Caption]:
        """``count`` different captions of a clip with these parameters."""
        return render(self.name, self.templates, self.slots(params), rng, held_out, count, self.core(params))


FAMILIES: dict[str, Family] = {}


def register(family: Family) -> Family:
    if family.name in FAMILIES:
        raise ValueError(f"family '{family.name}' is registered twice")
    FAMILIES[family.name] = family
    return family


def family_names() -> tuple[str, ...]:
    """All registered family names, in registration order."""
    import controlmm.corpus.families  # noqa: F401  (registers the families)

    return tuple(FAMILIES)


def get_family(name: str) -> Family:
    """The family called ``name``; a one-line error lists the valid names otherwise."""
    names = family_names()
    if name not in FAMILIES:
        raise ControlMMError(f"unknown motion family '{name}'; valid families: {', '.join(names)}")
    return FAMILIES[name]
