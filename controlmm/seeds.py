"""Random seeds: the one range every command and API accepts."""

from __future__ import annotations

import operator

from controlmm.errors import ControlMMError

SEED_MAX = 2**63 - 1
"""Largest seed: seeds are stored as signed 64-bit integers (torch generators, npz, JSON)."""


def check_seed(seed: int, name: str = "seed") -> int:
    """Return ``seed`` as an int if it is in ``[0, SEED_MAX]``; else a one-line ControlMMError."""
    try:
        value = None if isinstance(seed, bool) else operator.index(seed)  # int or numpy integer
    except TypeError:
        value = None
    if value is None or not 0 <= value <= SEED_MAX:
        raise ControlMMError(f"{name} must be an integer from 0 to {SEED_MAX} (2^63 - 1); got {seed!r}")
    return value
