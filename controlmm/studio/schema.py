"""The HTTP API's plan request: JSON fields -> a checked :class:`~controlmm.pipeline.PlanConfig`.

``POST /api/plans`` takes the fields of ``PlanConfig`` that a request may set (:data:`FIELDS`);
every bad value is a :class:`RequestError` naming the field, answered with HTTP 400 and one line.
Everything that can be known before planning is checked here, so a plan that is accepted runs:
field types and ranges, the robot, the scene (it compiles, the robot's start pose is clear of its
obstacles), the control spec (well formed, every frame inside the motion) and the timeline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from controlmm.control.spec import ControlSpec
from controlmm.errors import ControlMMError
from controlmm.generate.api import frames_for
from controlmm.motion.skeleton import MAX_FRAMES
from controlmm.pipeline import PlanConfig
from controlmm.pipeline.inputs import plan_seconds, start_pose_error
from controlmm.pipeline.plan import resolve_inputs
from controlmm.timeline import as_timeline
from retarget import load_robot
from scenes import Scene, load_scene

_STR, _NUM, _INT, _BOOL = "a string", "a number", "a whole number", "true or false"
FIELDS: dict[str, tuple[str, bool]] = {
    "scene": (_STR, False),
    "text": (_STR, True),
    "control": ("a control spec object or a spec .json path", True),
    "robot": (_STR, False),
    "seconds": (_NUM, True),
    "seed": (_INT, False),
    "rounds": (_INT, False),
    "preset": (_STR, False),
    "fps": (_NUM, False),
    "safe_distance_m": (_NUM, False),
    "render": (_BOOL, False),
    "plots": (_BOOL, False),
    "timeline": ("a timeline object or a timeline .json path", True),
}
"""Request fields: (what the value must be, whether null is allowed). Unset fields take the
``PlanConfig`` defaults, except :data:`SERVICE_DEFAULTS`."""

SERVICE_DEFAULTS: dict[str, Any] = {"render": False, "plots": False}
"""The service writes no video and no PNG plots unless asked (``"render": true``, ``"plots": true``):
the page draws the same in 3-D, and they would double a plan's time."""


class RequestError(ControlMMError):
    """A bad request field: HTTP 400 with ``{"error": message, "field": field}``."""

    def __init__(self, field: str | None, message: str) -> None:
        super().__init__(message)
        self.field = field


def _check_type(name: str, value: Any) -> Any:
    kind, nullable = FIELDS[name]
    if value is None:
        if nullable:
            return None
        raise RequestError(name, f"{name} must be {kind}; got null")
    ok = {
        _STR: isinstance(value, str),
        _NUM: isinstance(value, (int, float)) and not isinstance(value, bool),
        _INT: isinstance(value, int) and not isinstance(value, bool),
        _BOOL: isinstance(value, bool),
    }.get(kind, isinstance(value, (str, dict)))
    if not ok:
        raise RequestError(name, f"{name} must be {kind}; got {_show(value)}")
    if kind == _NUM and not math.isfinite(float(value)):
        raise RequestError(name, f"{name} must be a finite number; got {value}")
    return float(value) if kind == _NUM else value


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass(frozen=True)
class PlanRequest:
    """A checked request: the config to plan and the scene it loaded while checking."""

    config: PlanConfig
    scene: Scene


def parse_plan_request(body: Any, model: str | None = None) -> PlanRequest:
    """Check a ``POST /api/plans`` body and build its :class:`PlanConfig` (``model``: the service's).

    Raises:
        RequestError: the first bad field, with a one-line message.
    """
    if not isinstance(body, dict):
        raise RequestError(None, f"the request body must be a JSON object of plan fields; got {_show(body)}")
    unknown = sorted(set(body) - set(FIELDS))
    if "model" in unknown:
        raise RequestError(
            "model", "the model is chosen when the studio starts (controlmm studio --model DIR)"
        )
    if unknown:
        raise RequestError(unknown[0], f"unknown field '{unknown[0]}'; allowed fields: {', '.join(FIELDS)}")
    fields = {**SERVICE_DEFAULTS, **{k: _check_type(k, v) for k, v in body.items()}}
    if isinstance(fields.get("control"), str) and not fields["control"].strip():
        fields["control"] = None
    for name, value in fields.items():  # PlanConfig's own range checks, each blamed on its field
        if name in ("control", "timeline", "robot", "scene"):
            continue
        try:
            PlanConfig(**{name: value})
        except ControlMMError as exc:
            raise RequestError(name, str(exc)) from None
    try:
        config = PlanConfig(**fields)
    except ControlMMError as exc:  # a combination (text and timeline)
        raise RequestError("timeline" if "timeline" in body else None, str(exc)) from None
    config = replace(config, model=model)
    try:
        load_robot(config.robot)
    except ControlMMError as exc:
        raise RequestError("robot", str(exc)) from None
    try:
        scene = load_scene(config.scene, robot=config.robot)
    except ControlMMError as exc:
        raise RequestError("scene", str(exc)) from None
    error = start_pose_error(scene)
    if error:
        raise RequestError("scene", error)
    if config.timeline is not None:
        try:
            as_timeline(config.timeline)
        except ControlMMError as exc:
            raise RequestError("timeline", str(exc)) from None
    try:
        _, _, spec, _ = resolve_inputs(config)
    except ControlMMError as exc:
        raise RequestError("control" if config.control is not None else "text", str(exc)) from None
    if spec is not None:
        try:
            seconds = plan_seconds(config.seconds, spec)  # None: past the longest motion
            spec.check_length(MAX_FRAMES if seconds is None else frames_for(1, seconds)[0])
        except ControlMMError as exc:
            raise RequestError("control", str(exc)) from None
    return PlanRequest(config, scene)


def parse_spec(body: Any) -> ControlSpec:
    """A control spec from a request's ``control`` value (an object), or a RequestError."""
    if not isinstance(body, dict):
        raise RequestError("control", f"a control spec must be a JSON object; got {_show(body)}")
    try:
        return ControlSpec.from_dict(body)
    except ControlMMError as exc:
        raise RequestError("control", str(exc)) from None
