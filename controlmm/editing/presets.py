"""Editing settings and the named presets of the paper (ControlMM, arXiv:2410.10780: A.3/A.4, Table 5).

| preset | motion control model | logits editing (per decoding iteration) | codebook editing (at the end) |
|---|---|---|---|
| ``fast`` | on | 0 | 100 |
| ``medium`` | on | 0 | 600 |
| ``accurate`` | on | 100 | 600 (+ up to 200 in the foot-contact run) |

Step counts are maxima: every editor stops as soon as every constraint is within ``tolerance``
(default 1 cm) and every other loss term is at most ``loss_tolerance``; the steps actually used are
reported. Optimiser (official code): a fresh AdamW per editing run, lr 0.06, betas (0.5, 0.9),
weight decay 1e-6; Gumbel-softmax temperature 1.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from controlmm.errors import ControlMMError


@dataclass(frozen=True)
class EditingConfig:
    """How a controlled generation uses the control model and the two editors (``name``: for records)."""

    name: str = "custom"
    control_model: bool = True
    logits_steps: int = 100  # per decoding iteration
    codebook_steps: int = 600  # once, after the residual layers
    lr: float = 0.06  # AdamW learning rate of codebook editing with codebook_optimizer="adam"
    logits_lr: float = 0.3  # AdamW learning rate of logits editing
    logits_patience: int = 10  # logits editing stops on a plateau of this many steps (0: never)
    logits_warm_start: bool = True  # each decoding iteration's editing starts from the last one's edit
    logits_warm_patience: int = 5  # logits_patience of a warm-started iteration (it starts on the plateau)
    codebook_optimizer: str = (
        "lbfgs"  # "adam" (the paper's AdamW) or "lbfgs" (quasi-Newton, steps = evaluations)
    )
    betas: tuple[float, float] = (0.5, 0.9)
    weight_decay: float = 1e-6
    temperature: float = 1.0  # Gumbel-softmax temperature of logits editing
    tolerance: float = 0.01  # metres: stop when every constraint is this close
    logits_tolerance: float = 0.03  # metres: logits editing stops when its motion estimate is this close
    hinge_weight: float = 10.0  # codebook editing: weight of the hinge on lagging constraints (Objective)
    difference_weight: float = 30.0  # codebook editing: weight of the keyframe-difference term (Objective)
    loss_tolerance: float = 1e-6  # stop when every other loss term is at most this
    early_stop: bool = True
    contact_steps: int = 0  # codebook-editing steps of the foot-contact run after codebook editing (0: off)
    contact_hinge_weight: float = 3.0  # the foot-contact run's hinge weight (see foot_contact_run)
    contact_weight: float = 0.3  # weight of the foot-contact term in that run ((m/s)^2)

    def __post_init__(self) -> None:
        for name in ("logits_steps", "codebook_steps", "contact_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ControlMMError(f"{name} must be a whole number >= 0; got {value!r}")
        if self.codebook_optimizer not in ("adam", "lbfgs"):
            raise ControlMMError(f"codebook_optimizer must be adam or lbfgs; got '{self.codebook_optimizer}'")
        for name in ("logits_patience", "logits_warm_patience"):
            if getattr(self, name) < 0:
                raise ControlMMError(f"{name} must be >= 0; got {getattr(self, name)}")
        for name in ("difference_weight", "contact_hinge_weight"):
            if not getattr(self, name) >= 0:
                raise ControlMMError(f"{name} must be >= 0; got {getattr(self, name)}")
        for name in ("lr", "logits_lr", "temperature", "contact_weight"):
            if not getattr(self, name) > 0:
                raise ControlMMError(f"{name} must be positive; got {getattr(self, name)}")
        if not self.tolerance > 0 or not self.logits_tolerance > 0:
            raise ControlMMError(
                f"tolerances must be positive (metres); got {self.tolerance}, {self.logits_tolerance}"
            )
        if self.loss_tolerance < 0:
            raise ControlMMError(f"loss_tolerance must be >= 0; got {self.loss_tolerance}")

    def with_overrides(self, **changes: Any) -> EditingConfig:
        """A copy with the non-None ``changes`` applied."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


PRESETS: dict[str, EditingConfig] = {
    "fast": EditingConfig(name="fast", control_model=True, logits_steps=0, codebook_steps=100),
    "medium": EditingConfig(name="medium", control_model=True, logits_steps=0, codebook_steps=600),
    # + the foot-contact run (not in the paper): 200 more steps that stop planted feet sliding. Without
    # the keyframe-difference term: with it (and logits editing's warm start), codebook editing ends
    # on motions whose planted feet the run cannot free without breaking a constraint (docs/control.md)
    "accurate": EditingConfig(
        name="accurate",
        control_model=True,
        logits_steps=100,
        codebook_steps=600,
        contact_steps=200,
        difference_weight=0.0,
    ),
}
"""The paper's presets (Table 5): ControlMM-Fast, -Medium, -Accurate."""


def editing_preset(preset: str | EditingConfig) -> EditingConfig:
    """The :class:`EditingConfig` of a preset name (``fast``, ``medium``, ``accurate``) or the config
    itself."""
    if isinstance(preset, EditingConfig):
        return preset
    if preset not in PRESETS:
        raise ControlMMError(f"unknown editing preset '{preset}'; allowed: {', '.join(PRESETS)}")
    return PRESETS[preset]
