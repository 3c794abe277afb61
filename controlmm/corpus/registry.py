"""The motion-family registry: every family by name, in a fixed order.

A family (:class:`~controlmm.corpus.family.Family`) knows how to draw random parameters, build the
motion for them, and describe it (caption templates, slot fillers and the claims its words make).
Each family module holds its families in ``FAMILIES``; :data:`GROUPS` lists the modules, and their
order (then each module's own) is the registry order.
"""

from __future__ import annotations

from collections.abc import Iterable
from types import ModuleType

from controlmm.corpus.families import (
    actions,
    combos,
    gestures,
    jumping,
    lowering,
    postures,
    reaching,
    sequences,
    terrain,
    turning,
    walking,
)
from controlmm.corpus.family import Family
from controlmm.errors import ControlMMError

GROUPS: tuple[ModuleType, ...] = (
    walking,
    turning,
    jumping,
    lowering,
    gestures,
    reaching,
    combos,
    postures,
    actions,
    terrain,
    sequences,
)
"""The family modules in registry order (the 32 first families, then postures, actions, terrain and
sequences; the order of the families is the order of ``controlmm corpus --list``)."""


def _by_name(families: Iterable[Family]) -> dict[str, Family]:
    out: dict[str, Family] = {}
    for family in families:
        if family.name in out:
            raise ValueError(f"family '{family.name}' is registered twice")
        out[family.name] = family
    return out


FAMILIES: dict[str, Family] = _by_name(f for group in GROUPS for f in group.FAMILIES)
"""Every family by name, in registry order."""


def family_names() -> tuple[str, ...]:
    """All family names, in registry order."""
    return tuple(FAMILIES)


def get_family(name: str) -> Family:
    """The family called ``name``; a one-line error lists the valid names otherwise."""
    if name not in FAMILIES:
        raise ControlMMError(f"unknown motion family '{name}'; valid families: {', '.join(FAMILIES)}")
    return FAMILIES[name]
