"""A motion family: how to draw parameters, build the motion and caption it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from controlmm.corpus.scene import Scene
from controlmm.corpus.text.templates import Caption, Slot, Template, render

Params = dict[str, Any]


@dataclass(frozen=True)
class Built:
    """What a family that moves around objects builds: the joints (T + 1, 22, 3) and the scene
    (seat, platform, stairs, obstacle) in the same world frame."""

    joints: np.ndarray
    scene: Scene


@dataclass(frozen=True)
class Family:
    """A kind of motion.

    Attributes:
        name: registry name (also the probe's name).
        group: family module ("walking", "turning", "jumping", "lowering", "gestures", "combos").
        sample: rng -> JSON-serialisable parameters (speed, direction, hand, count...).
        build: (params, rng) -> joints (T + 1, 22, 3), metres, Y up; T in 40..196; or a
            :class:`Built` (joints and scene geometry).
        templates: caption patterns.
        slots: params -> fillers of the patterns' fields (with claims).
        core: params -> claims every caption of the family makes.
    """

    name: str
    group: str
    sample: Callable[[np.random.Generator], Params]
    build: Callable[[Params, np.random.Generator], np.ndarray | Built]
    templates: tuple[Template, ...]
    slots: Callable[[Params], dict[str, Slot]]
    core: Callable[[Params], dict[str, Any]] = lambda p: {}

    def captions(
        self, params: Params, rng: np.random.Generator, held_out: bool, count: int = 3
    ) -> list[Caption]:
        """``count`` different captions of a clip with these parameters."""
        return render(self.name, self.templates, self.slots(params), rng, held_out, count, self.core(params))
