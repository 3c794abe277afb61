"""Mapping files: which robot body (or site) follows which human joint, and how strongly.

A mapping is a JSON file (``retarget/mappings/g1.json`` is the reference)::

    {
      "format": "controlmm-retarget-mapping/1",
      "robot": "g1",                       # packaged robot name, or an MJCF path (relative to this file)
      "scale": "auto",                     # or a number: the human -> robot uniform scale
      "keypoints": {                       # HumanML3D joint name -> robot target
        "pelvis":     {"body": "pelvis", "position_weight": 3, "orientation_weight": 2},
        "left_foot":  {"body": "left_ankle_roll_link", "offset": [0.10, 0, -0.034]},
        "left_wrist": {"site": "left_palm"},          # a site of the MJCF instead of a body
        ...
      },
      "posture_weights": {"default": 0.02, "left_wrist_roll_joint": 0.3},
      "body_joints": {"left_knee_link": ["left_knee"], ...}
    }

Keypoint fields: ``body`` or ``site`` (exactly one), ``offset`` (metres, in the body or site
frame), ``position_weight`` (absolute position), ``segment_weight`` (the vector from the
nearest mapped human ancestor), ``orientation_weight`` (only for joints whose orientation
the human motion gives: pelvis, spine3 and the feet). ``pelvis``, ``left_ankle`` and
``right_ankle`` are required: the pelvis places the floating base, the ankles' bodies are the
feet (their collision geoms touch the floor). ``body_joints`` lists, per robot body, the
human joints it follows (the simulation feedback loop turns a failure on a body into a loss
on those joints); bodies left out get the joints of their nearest mapped descendant (else
ancestor).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field, fields
from pathlib import Path

from controlmm.errors import ControlMMError, InputFileError
from controlmm.motion.skeleton import JOINT_NAMES
from retarget.robots import PACKAGED_ROBOTS
from retarget.solver_config import SolverConfig

MAPPING_FORMAT = "controlmm-retarget-mapping/1"
MAPPINGS_DIR = Path(__file__).resolve().parent / "mappings"

ORIENTED_JOINTS = ("pelvis", "spine3", "left_ankle", "right_ankle", "left_foot", "right_foot")
"""Human joints with an orientation target (pelvis frame, torso frame, foot frames)."""

REQUIRED_JOINTS = ("pelvis", "left_ankle", "right_ankle")

DEFAULT_WEIGHTS: dict[str, tuple[float, float, float]] = {
    # joint: (position_weight, segment_weight, orientation_weight)
    "pelvis": (3.0, 0.0, 2.0),
    "left_hip": (0.3, 1.0, 0.0),
    "right_hip": (0.3, 1.0, 0.0),
    "left_knee": (3.0, 2.0, 0.0),
    "right_knee": (3.0, 2.0, 0.0),
    "left_ankle": (3.0, 2.0, 1.0),
    "right_ankle": (3.0, 2.0, 1.0),
    "left_foot": (2.0, 1.0, 0.0),
    "right_foot": (2.0, 1.0, 0.0),
    "spine3": (0.5, 1.0, 1.0),
    "head": (0.3, 0.5, 0.0),
    "left_shoulder": (0.5, 1.0, 0.0),
    "right_shoulder": (0.5, 1.0, 0.0),
    "left_elbow": (3.0, 2.0, 0.0),
    "right_elbow": (3.0, 2.0, 0.0),
    "left_wrist": (3.0, 2.0, 0.0),
    "right_wrist": (3.0, 2.0, 0.0),
}
"""Weights used when a keypoint entry leaves them out (unlisted joints: 0.5, 1.0, 0.0)."""

_KEYPOINT_FIELDS = {"body", "site", "offset", "position_weight", "segment_weight", "orientation_weight"}
_TOP_FIELDS = {
    "format",
    "description",
    "robot",
    "scale",
    "keypoints",
    "posture_weights",
    "ranges",
    "arm_abduction",
    "body_joints",
    "solver",
}


@dataclass(frozen=True)
class Keypoint:
    """One human joint followed by a point of the robot.

    Attributes:
        joint: HumanML3D joint name.
        body: robot body name, or None when ``site`` is given.
        site: robot site name, or None.
        offset: (3,) metres, in the body (or site) frame.
        position_weight, segment_weight, orientation_weight: cost weights (>= 0).
    """

    joint: str
    body: str | None
    site: str | None
    offset: tuple[float, float, float]
    position_weight: float
    segment_weight: float
    orientation_weight: float


@dataclass(frozen=True)
class Mapping:
    """A parsed mapping file (not yet checked against the MJCF; see :mod:`retarget.robot_model`).

    Attributes:
        robot: packaged robot name (``g1``) or an absolute MJCF path.
        keypoints: the mapped human joints in HumanML3D order.
        scale: fixed human -> robot scale, or None for automatic (leg height ratio).
        posture_weights: joint name -> weight pulling that joint toward 0 (``default`` for others).
        ranges: joint name -> (lower, upper) rad the retargeter keeps the joint in (intersected
            with the MJCF range): human-like ranges for joints the robot can move further
            than a person (an elbow bending backwards, an upper arm twisted half a turn).
        arm_abduction: rad a hanging arm keeps away from the body's side
            (:func:`retarget.targets.abduct_arms`; 0: as the human's).
        body_joints: robot body -> human joints it follows (as written in the file).
        solver: :class:`retarget.solver_config.SolverConfig` fields this robot changes (e.g. ``levels``).
        source: where the mapping came from (file path or ``packaged:g1``).
        name: short name used in reports (the packaged robot name or the file stem).
    """

    robot: str
    keypoints: tuple[Keypoint, ...]
    scale: float | None = None
    posture_weights: dict[str, float] = field(default_factory=dict)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    arm_abduction: float = 0.0
    body_joints: dict[str, tuple[str, ...]] = field(default_factory=dict)
    solver: dict = field(default_factory=dict)
    source: str = ""
    name: str = ""

    def keypoint(self, joint: str) -> Keypoint | None:
        return next((k for k in self.keypoints if k.joint == joint), None)


def packaged_mappings() -> list[str]:
    """Names of the mapping files shipped with the package (``g1``, ``h1``)."""
    return sorted(p.stem for p in MAPPINGS_DIR.glob("*.json"))


def _number(value, what: str, minimum: float = 0.0) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ControlMMError(f"{what} must be a number; got {value!r}") from None
    if not (out == out and abs(out) != float("inf")) or out < minimum:
        raise ControlMMError(f"{what} must be a finite number >= {minimum}; got {value!r}")
    return out


def _parse_keypoint(joint: str, spec: dict, where: str) -> Keypoint:
    if joint not in JOINT_NAMES:
        raise ControlMMError(
            f"{where}: unknown human joint '{joint}'; valid joints: {', '.join(JOINT_NAMES)}"
        )
    if not isinstance(spec, dict):
        raise ControlMMError(f"{where}: keypoint '{joint}' must be an object with 'body' or 'site'")
    extra = set(spec) - _KEYPOINT_FIELDS
    if extra:
        raise ControlMMError(
            f"{where}: keypoint '{joint}' has unknown field(s) {sorted(extra)}; "
            f"allowed: {sorted(_KEYPOINT_FIELDS)}"
        )
    if ("body" in spec) == ("site" in spec):
        raise ControlMMError(f"{where}: keypoint '{joint}' needs exactly one of 'body' or 'site'")
    offset = spec.get("offset", [0.0, 0.0, 0.0])
    if not (isinstance(offset, (list, tuple)) and len(offset) == 3):
        raise ControlMMError(
            f"{where}: keypoint '{joint}' offset must be [x, y, z] in metres; got {offset!r}"
        )
    offset = tuple(_number(v, f"{where}: offset of '{joint}'", minimum=-10.0) for v in offset)
    pw, sw, ow = DEFAULT_WEIGHTS.get(joint, (0.5, 1.0, 0.0))
    pw = _number(spec.get("position_weight", pw), f"{where}: position_weight of '{joint}'")
    sw = _number(spec.get("segment_weight", sw), f"{where}: segment_weight of '{joint}'")
    ow = _number(
        spec.get("orientation_weight", ow if joint in ORIENTED_JOINTS else 0.0),
        f"{where}: orientation_weight of '{joint}'",
    )
    if ow > 0 and joint not in ORIENTED_JOINTS:
        raise ControlMMError(
            f"{where}: the human motion gives no orientation for '{joint}'; "
            f"orientation_weight is allowed for: {', '.join(ORIENTED_JOINTS)}"
        )
    body, site = spec.get("body"), spec.get("site")
    for name, val in (("body", body), ("site", site)):
        if val is not None and (not isinstance(val, str) or not val):
            raise ControlMMError(f"{where}: keypoint '{joint}' {name} must be a name; got {val!r}")
    return Keypoint(joint, body, site, offset, pw, sw, ow)


def parse_mapping(data: dict, source: str = "<mapping>", base_dir: Path | None = None) -> Mapping:
    """Build a :class:`Mapping` from the JSON object of a mapping file."""
    if not isinstance(data, dict):
        raise ControlMMError(f"{source}: a mapping must be a JSON object")
    fmt = data.get("format", MAPPING_FORMAT)
    if fmt != MAPPING_FORMAT:
        raise ControlMMError(f"{source}: unsupported mapping format '{fmt}'; expected '{MAPPING_FORMAT}'")
    extra = set(data) - _TOP_FIELDS
    if extra:
        raise ControlMMError(f"{source}: unknown field(s) {sorted(extra)}; allowed: {sorted(_TOP_FIELDS)}")
    robot = data.get("robot")
    if not isinstance(robot, str) or not robot.strip():
        raise ControlMMError(f"{source}: 'robot' must name a packaged robot or an MJCF path")
    robot = robot.strip()
    if robot.lower().endswith(".xml"):
        path = Path(robot).expanduser()
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.is_file():
            raise InputFileError(f"{source}: the robot MJCF '{robot}' does not exist (looked at {path})")
        robot = str(path.resolve())
    scale = data.get("scale", "auto")
    scale = None if scale in (None, "auto") else _number(scale, f"{source}: scale", minimum=1e-3)
    kps = data.get("keypoints")
    if not isinstance(kps, dict) or not kps:
        raise ControlMMError(f"{source}: 'keypoints' must map human joint names to robot bodies or sites")
    keypoints = [_parse_keypoint(j, s, source) for j, s in kps.items()]
    missing = [j for j in REQUIRED_JOINTS if j not in kps]
    if missing:
        raise ControlMMError(
            f"{source}: the mapping must map {', '.join(missing)} (required: {', '.join(REQUIRED_JOINTS)})"
        )
    keypoints.sort(key=lambda k: JOINT_NAMES.index(k.joint))
    posture = data.get("posture_weights", {})
    if not isinstance(posture, dict):
        raise ControlMMError(f"{source}: 'posture_weights' must map joint names to weights")
    posture = {str(k): _number(v, f"{source}: posture weight of '{k}'") for k, v in posture.items()}
    ranges_in = data.get("ranges", {})
    if not isinstance(ranges_in, dict):
        raise ControlMMError(f"{source}: 'ranges' must map joint names to [lower, upper] in radians")
    ranges: dict[str, tuple[float, float]] = {}
    for joint, pair in ranges_in.items():
        if not (isinstance(pair, (list, tuple)) and len(pair) == 2):
            raise ControlMMError(f"{source}: ranges['{joint}'] must be [lower, upper]; got {pair!r}")
        lo = _number(pair[0], f"{source}: ranges['{joint}'] lower", minimum=-float("inf"))
        hi = _number(pair[1], f"{source}: ranges['{joint}'] upper", minimum=-float("inf"))
        if not lo < hi:
            raise ControlMMError(f"{source}: ranges['{joint}'] must have lower < upper; got {pair!r}")
        ranges[str(joint)] = (lo, hi)
    arm_abduction = _number(data.get("arm_abduction", 0.0), f"{source}: arm_abduction")
    if arm_abduction >= 1.5:
        raise ControlMMError(f"{source}: arm_abduction must be below 1.5 rad; got {arm_abduction!r}")
    bj = data.get("body_joints", {})
    if not isinstance(bj, dict):
        raise ControlMMError(f"{source}: 'body_joints' must map robot body names to lists of human joints")
    body_joints: dict[str, tuple[str, ...]] = {}
    for body, joints in bj.items():
        if isinstance(joints, str):
            joints = [joints]
        if not isinstance(joints, (list, tuple)):
            raise ControlMMError(f"{source}: body_joints['{body}'] must be a list of human joint names")
        for j in joints:
            if j not in JOINT_NAMES:
                raise ControlMMError(
                    f"{source}: body_joints['{body}'] names unknown human joint '{j}'; "
                    f"valid joints: {', '.join(JOINT_NAMES)}"
                )
        body_joints[str(body)] = tuple(joints)
    solver = _parse_solver(data.get("solver", {}), source)
    name = robot if not robot.endswith(".xml") else Path(robot).stem
    return Mapping(
        robot=robot,
        keypoints=tuple(keypoints),
        scale=scale,
        posture_weights=posture,
        ranges=ranges,
        arm_abduction=arm_abduction,
        body_joints=body_joints,
        solver=solver,
        source=source,
        name=name,
    )


SHARES = ("human_leg_share", "human_arm_share", "foot_roll", "foot_lift")
"""Solver settings that are shares, from 0 to 1."""


def _parse_solver(spec, source: str) -> dict:
    """Validated SolverConfig overrides from the mapping's ``solver`` object."""
    if not isinstance(spec, dict):
        raise ControlMMError(f"{source}: 'solver' must be an object of solver settings")
    allowed = {f.name: f for f in fields(SolverConfig)}
    out: dict = {}
    for key, value in spec.items():
        if key not in allowed:
            raise ControlMMError(
                f"{source}: unknown solver setting '{key}'; allowed: {', '.join(sorted(allowed))}"
            )
        if key == "levels":
            try:
                levels = tuple((int(k), int(n)) for k, n in value)
            except (TypeError, ValueError):
                raise ControlMMError(
                    f"{source}: solver levels must be [[every_kth_frame, iterations], ...]"
                ) from None
            if not levels or any(k < 1 or n < 1 for k, n in levels) or levels[-1][0] != 1:
                raise ControlMMError(
                    f"{source}: solver levels must be positive and end with every frame ([1, n])"
                )
            out[key] = levels
        elif key == "exact_acceleration":
            out[key] = bool(value)
        elif key in SHARES:
            out[key] = _number(value, f"{source}: solver {key}")
            if out[key] > 1.0:
                raise ControlMMError(f"{source}: solver {key} must be a number from 0 to 1; got {value!r}")
        elif allowed[key].type in ("int", int):
            out[key] = int(_number(value, f"{source}: solver {key}"))
        else:
            out[key] = _number(value, f"{source}: solver {key}")
    return out


def load_mapping(name_or_path: str | Path) -> Mapping:
    """Load a mapping by packaged robot name (``g1``, ``h1``) or from a JSON file path."""
    text = str(name_or_path).strip()
    if not text.lower().endswith(".json"):
        key = text.lower()
        path = MAPPINGS_DIR / f"{key}.json"
        if not re.fullmatch(r"[a-z0-9_\-]+", key) or not path.is_file():
            known = sorted(set(packaged_mappings()))
            hint = ""
            if key in PACKAGED_ROBOTS:
                hint = f" (robot '{key}' is packaged but has no shipped mapping; pass a mapping file)"
            raise ControlMMError(
                f"unknown robot '{text}'{hint}; known robots: {', '.join(known)}; "
                "or pass a mapping .json or a humanoid MJCF .xml"
            )
        source = f"packaged:{key}"
    else:
        path = Path(text).expanduser()
        if not path.is_file():
            raise InputFileError(f"mapping file '{text}' does not exist")
        source = str(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputFileError(
            f"mapping file '{path}' is not valid JSON: {exc.msg} (line {exc.lineno})"
        ) from None
    return parse_mapping(data, source=source, base_dir=path.parent)
