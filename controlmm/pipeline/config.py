"""Settings of one ``plan`` run (:class:`PlanConfig`)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from controlmm.editing.presets import editing_preset
from controlmm.errors import ControlMMError
from controlmm.pipeline.clip import MAX_CLIP_SECONDS
from controlmm.pipeline.feedback import FeedbackConfig
from controlmm.seeds import check_seed
from retarget.exports import parse_formats
from sim.config import CheckConfig
from sim.physics import PhysicsConfig

DEFAULT_SCENE = "table"
"""The bundled example: a table to keep clear of and a right-hand target beyond its edge."""


@dataclass(frozen=True)
class PlanConfig:
    """What to plan and how.

    Attributes:
        scene: packaged scene name or an MJCF path (``controlmm scene list``).
        text: the prompt; None uses the scene's suggested prompt.
        control: a control-spec JSON path, a spec dict, or None. With neither ``text`` nor
            ``control`` given, the scene's suggested control is used (the bundled example);
            with a ``text`` of your own, no control unless you give one.
        robot: packaged robot (``controlmm robots``), a humanoid MJCF ``.xml`` or a mapping ``.json``.
        seconds: motion length (2..9.8 s); None: 6 s without a control spec, with one 0.5 s past
            its last constraint (at least 2 s, at most 6 s unless a constraint comes later).
        seed: reproducibility (generation sampling).
        rounds: feedback rounds after the first generation (0 = check only).
        preset: editing preset (``fast``, ``medium``, ``accurate``).
        model: model directory; None = the embedded default.
        fps: robot trajectory rate (Hz).
        safe_distance_m: clearance the obstacle loss keeps from every obstacle (world m).
        render: write ``render.mp4``; render_fps / render_size: its frame rate and (width, height).
        plots: write ``plots/*.png``.
        timeline: a body-part timeline spec (JSON path) instead of ``text`` (when supported).
        motion: a recorded clip to edit instead of generating (any file of
            ``controlmm.motion.load_motion``; :mod:`controlmm.pipeline.clip`); ``seconds`` then cuts it
            (2 to 30 s from ``motion_start``) and only ``control`` given here constrains it.
        motion_import: keyword arguments of ``load_motion`` for the clip (``up``, ``fps``, ``mapping``,
            ``units``).
        motion_start: where the edited window of the clip starts (s).
        closeness_weight: weight of the term that keeps the edited motion on the clip.
        formats: robot trajectory formats written beside ``robot.npz``/``robot.json``
            (``retarget.exports``: lafan1, qpos, beyondmimic, gmr).
        feedback: how failures become loss terms.
        check: thresholds of the simulation checks (``sim.CheckConfig``; default: its defaults);
            ``CheckConfig(physics=True)`` executes every round in physics as its last check.
        physics: settings of that physics execution check (``sim.PhysicsConfig``).
    """

    scene: str = DEFAULT_SCENE
    text: str | None = None
    control: str | dict | None = None
    robot: str = "g1"
    seconds: float | None = None
    seed: int = 0
    rounds: int = 3
    preset: str = "accurate"
    model: str | None = None
    fps: float = 50.0
    safe_distance_m: float = 0.03
    render: bool = True
    render_fps: float = 25.0
    render_size: tuple[int, int] = (480, 360)
    plots: bool = True
    timeline: str | None = None
    motion: str | None = None
    motion_import: dict[str, Any] = field(default_factory=dict)
    motion_start: float = 0.0
    closeness_weight: float = 1.0
    formats: tuple[str, ...] = ("lafan1",)
    feedback: FeedbackConfig = field(default_factory=FeedbackConfig)
    check: CheckConfig = field(default_factory=CheckConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)

    def __post_init__(self) -> None:
        if isinstance(self.rounds, bool) or not isinstance(self.rounds, int) or not 0 <= self.rounds <= 10:
            raise ControlMMError(f"rounds must be a whole number from 0 to 10; got {self.rounds!r}")
        longest = MAX_CLIP_SECONDS if self.motion is not None else 9.8
        if self.seconds is not None and not (math.isfinite(self.seconds) and 2.0 <= self.seconds <= longest):
            raise ControlMMError(
                f"seconds must be from 2 to {longest:g} (40..{round(longest * 20)} frames at 20 fps); "
                f"got {self.seconds}"
            )
        check_seed(self.seed)
        if not (math.isfinite(self.fps) and 10 <= self.fps <= 1000):
            raise ControlMMError(f"fps must be from 10 to 1000; got {self.fps}")
        if not (math.isfinite(self.safe_distance_m) and 0 <= self.safe_distance_m <= 0.5):
            raise ControlMMError(f"safe distance must be from 0 to 0.5 m; got {self.safe_distance_m}")
        if self.text is not None and not self.text.strip():
            raise ControlMMError("text is empty; give a prompt such as 'a person walks forward'")
        editing_preset(self.preset)  # an unknown preset fails here, naming the allowed ones
        if self.text is not None and self.timeline is not None:
            raise ControlMMError("give either a text prompt or a timeline, not both")
        if self.motion is not None and self.timeline is not None:
            raise ControlMMError("give either a motion to edit or a timeline, not both")
        if not (math.isfinite(self.motion_start) and self.motion_start >= 0):
            raise ControlMMError(f"motion start must be a time >= 0 s; got {self.motion_start}")
        if not (math.isfinite(self.closeness_weight) and self.closeness_weight >= 0):
            raise ControlMMError(f"closeness weight must be a number >= 0; got {self.closeness_weight}")
        object.__setattr__(self, "formats", parse_formats(self.formats))

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["check"] = self.check.to_dict()
        out["physics"] = self.physics.to_dict()
        if isinstance(self.control, (str, Path)):
            out["control"] = str(self.control)
        return out
