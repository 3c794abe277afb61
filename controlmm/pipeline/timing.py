"""Where a plan's time goes: wall seconds per stage, for ``report.json`` and the printed summary.

Stages, in order (:data:`STAGES`; a stage that did not run is left out):

========================  ================================================================================
``startup``               the command's start-up (interpreter, imports; the CLI only) and the plan's set-up:
                          inputs, scene, SDF, robot world, loading the model when it is not given
``text``                  the prompt's text embedding (the embedding cache or the text model)
``decoding``              masked decoding of the tokens (transformer and control-model passes, sampling,
                          residual layers) and decoding latents to motions
``logits_editing``        logits editing inside the decoding iterations
``codebook_editing``      codebook editing of the decoded latent
``foot_contact``          the foot-contact editing run
``timeline``              a body-part timeline's generation (instead of the four above)
``retarget``              human motion -> robot joint trajectory (round 0)
``checks``                the MuJoCo checks (round 0)
``feedback_rounds``       every feedback round: its editing, retargeting and checks (each round's own
                          split is in ``rounds[i].seconds``)
``outputs``               writing the files (motion, robot trajectory, plots, video)
``other``                 what the stages above do not cover (bookkeeping between them)
========================  ================================================================================

``total`` is the wall time from the start (of the command for the CLI: its first import of
:mod:`controlmm.cli`; of :func:`plan` in Python) to
the end of the last stage; the stages and ``other`` add up to it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

STAGES: tuple[str, ...] = (
    "startup",
    "text",
    "decoding",
    "logits_editing",
    "codebook_editing",
    "foot_contact",
    "timeline",
    "retarget",
    "checks",
    "feedback_rounds",
    "outputs",
)
"""The stages of a plan, in the order they run and are reported."""

LABELS: dict[str, str] = {
    "startup": "start-up",
    "logits_editing": "logits editing",
    "codebook_editing": "codebook editing",
    "foot_contact": "foot contact",
    "feedback_rounds": "feedback rounds",
}


@dataclass
class StageTimes:
    """Wall seconds per stage (:data:`STAGES`) and the total they belong to.

    ``origin`` is the :func:`time.perf_counter` value the total counts from.
    """

    origin: float = field(default_factory=time.perf_counter)
    seconds: dict[str, float] = field(default_factory=dict)
    end: float | None = None

    def add(self, stage: str, seconds: float) -> None:
        """Add ``seconds`` to ``stage``."""
        self.seconds[stage] = self.seconds.get(stage, 0.0) + max(0.0, float(seconds))

    def add_all(self, phases: Mapping[str, float]) -> None:
        for stage, seconds in phases.items():
            self.add(stage, seconds)

    def start_earlier(self, seconds: float) -> None:
        """Count ``seconds`` before ``origin`` as start-up (the command's time before the plan)."""
        self.origin -= seconds
        self.add("startup", seconds)

    def stop(self) -> None:
        """Mark the end of the timed work (the total counts up to here)."""
        self.end = time.perf_counter()

    @property
    def total(self) -> float:
        return (self.end if self.end is not None else time.perf_counter()) - self.origin

    def ordered(self) -> dict[str, float]:
        """Seconds per stage in :data:`STAGES` order (other names after), with ``other``."""
        names = [s for s in STAGES if s in self.seconds] + [s for s in self.seconds if s not in STAGES]
        out = {name: self.seconds[name] for name in names}
        out["other"] = max(0.0, self.total - sum(out.values()))
        return out

    def to_dict(self) -> dict[str, object]:
        """``report.json``'s ``timing``: seconds per stage, the total, and the machine's load."""
        try:
            load = [round(x, 2) for x in os.getloadavg()]
        except OSError:
            load = []
        return {
            "stages_s": {k: round(v, 3) for k, v in self.ordered().items()},
            "total_s": round(self.total, 3),
            "load_average": load,
        }

    def summary(self) -> str:
        """One line: ``timing: start-up 1.2 s, text 0.0 s, ...; total 6.1 s``."""
        parts = [f"{LABELS.get(k, k)} {v:.1f} s" for k, v in self.ordered().items() if k != "other"]
        return f"timing: {', '.join(parts)}; total {self.total:.1f} s"
