"""Thresholds and options of the simulation checks (:class:`CheckConfig`).

Every default is justified in ``docs/simulation-checks.md``. Units: metres, radians,
seconds, newtons; ratios are dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Literal

from controlmm.errors import ControlMMError
from retarget.actuators import DEFAULT_VELOCITY_LIMIT, PUBLISHED_VELOCITY_LIMITS

SelfCollisionMode = Literal["model", "capsules", "off"]


@dataclass(frozen=True)
class CheckConfig:
    """Options and thresholds of :func:`sim.check_trajectory`.

    A frame fails a check when its measured value exceeds the threshold (strictly). See
    ``docs/simulation-checks.md`` for the reasoning behind each default.

    Attributes:
        obstacle_penetration_m: allowed depth of a robot geom inside a scene obstacle.
        floor_penetration_m: allowed depth of the lowest robot collision point below the floor.
        self_collision_m: allowed depth of robot-robot contacts.
        self_collision: ``"model"`` (the MJCF's own collision geometry, exclusions and
            MuJoCo's parent-child filter), ``"capsules"`` (every robot mesh collider replaced by
            a capsule fitted to it, same filters) or ``"off"``.
        joint_limit_tol_rad: allowed overshoot past a joint's range (rad or m for slides).
        joint_coupling_tol_rad: allowed distance of a joint the MJCF couples to another
            (``<equality><joint>``) from where the coupling puts it (rad or m for slides).
        velocity_limits: per-joint velocity limits (rad/s) overriding the published table.
        default_velocity_limit: limit for joints with no published or configured value.
        velocity_limit_factor: fraction of the limit that is allowed (1.0 = the limit itself).
        stance_height_m: a foot is in stance when one of its collision geoms is closer than
            this to a support surface (floor or obstacle) in two consecutive frames.
        max_foot_slide_speed: allowed horizontal speed (m/s) of a stance foot.
        support_height_m: the robot is supported in a frame when any of its collision geoms
            is closer than this to the floor or an obstacle.
        max_flight_s: longest unsupported phase that may count as a flight (jump, run).
        ballistic_tol_m: a flight must follow a ballistic centre-of-mass height within this RMS.
        flight_edge_s: the ballistic fit leaves out this much of each end of an unsupported
            phase (take-off and landing impulses smeared over the frames around contact).
        clearance_sense_m: obstacle distances are measured up to this far (MuJoCo ``gap``).
        dynamics: run the inverse-dynamics feasibility check.
        max_residual_force_ratio: non-physical root force, as a fraction of m g, above which a
            frame gets a ``residual_force`` warning.
        max_residual_moment_m: non-physical moment about the centre of mass divided by m g
            (an equivalent centre-of-pressure error in metres) above which a frame gets a
            ``residual_moment`` warning.
        max_torque_ratio: |joint torque| / torque limit above which a frame gets a
            ``torque_limit`` warning.
        sustained_window_s: the window (s, centred) of the sustained dynamic checks.
        max_sustained_residual_force_ratio: the residual force averaged (as a vector, over
            supported frames) over the window, as a fraction of m g, above which the motion
            fails (``residual_force`` error): a hand of god the support cannot replace.
        max_sustained_residual_moment_m: the same for the residual moment / (m g) (metres).
        max_sustained_torque_ratio: |joint torque| / limit averaged over the window above
            which the motion fails (``torque_limit`` error).
        strict_dynamics: make every per-frame dynamic exceedance an error (as the sustained
            ones), not a warning.
        friction: contact friction coefficient for the support (None: from the model's geoms).
        substeps: extra linearly interpolated poses checked between consecutive frames
            (0 = only the given frames).
        tracking: also run the PD-tracking replay in physics (slower; reports falls).
        tracking_kp, tracking_kd: PD gains of that replay (N m/rad, N m s/rad).
        fall_height_ratio: the robot has fallen when its root height drops below this fraction
            of the reference root height.
        physics: also execute the trajectory in physics with the predictive tracking controller
            (``sim.track``; slow: seconds of computation per second of motion). Its settings are
            a ``sim.PhysicsConfig`` given to ``check_trajectory(physics=...)``.
    """

    obstacle_penetration_m: float = 0.005
    floor_penetration_m: float = 0.005
    self_collision_m: float = 0.005
    self_collision: SelfCollisionMode = "model"
    joint_limit_tol_rad: float = 1e-4
    joint_coupling_tol_rad: float = 0.01
    velocity_limits: dict[str, float] = field(default_factory=dict)
    default_velocity_limit: float = DEFAULT_VELOCITY_LIMIT
    velocity_limit_factor: float = 1.0
    stance_height_m: float = 0.01
    max_foot_slide_speed: float = 0.2
    support_height_m: float = 0.02
    max_flight_s: float = 0.8
    ballistic_tol_m: float = 0.025
    flight_edge_s: float = 0.1
    clearance_sense_m: float = 0.1
    dynamics: bool = True
    max_residual_force_ratio: float = 0.1
    max_residual_moment_m: float = 0.03
    max_torque_ratio: float = 1.0
    sustained_window_s: float = 0.5
    max_sustained_residual_force_ratio: float = 0.5
    max_sustained_residual_moment_m: float = 0.1
    max_sustained_torque_ratio: float = 1.0
    strict_dynamics: bool = False
    friction: float | None = None
    substeps: int = 0
    tracking: bool = False
    tracking_kp: float = 500.0
    tracking_kd: float = 10.0
    fall_height_ratio: float = 0.6
    physics: bool = False

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or f.name in ("self_collision", "velocity_limits", "friction"):
                continue
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ControlMMError(f"CheckConfig.{f.name} must be a finite number >= 0; got {value!r}")
        if self.self_collision not in ("model", "capsules", "off"):
            raise ControlMMError(
                "CheckConfig.self_collision must be 'model', 'capsules' or 'off'; "
                f"got {self.self_collision!r}"
            )
        if self.friction is not None and not (math.isfinite(self.friction) and self.friction > 0):
            raise ControlMMError(f"CheckConfig.friction must be > 0 or None; got {self.friction!r}")
        for name, limit in self.velocity_limits.items():
            if not (math.isfinite(limit) and limit > 0):
                raise ControlMMError(f"velocity limit of joint '{name}' must be > 0; got {limit!r}")
        if int(self.substeps) != self.substeps:
            raise ControlMMError(f"CheckConfig.substeps must be an integer >= 0; got {self.substeps!r}")
        if not 0 < self.fall_height_ratio < 1:
            raise ControlMMError(
                f"CheckConfig.fall_height_ratio must be in (0, 1); got {self.fall_height_ratio!r}"
            )

    def velocity_limit(self, joint_name: str) -> float:
        """Velocity limit (rad/s) of a joint: configured, else published, else the default.

        A namespace prefix from MJCF attachment (``robot/left_knee_joint``) is ignored when
        looking up the published table.
        """
        bare = joint_name.rsplit("/", 1)[-1]
        limit = self.velocity_limits.get(joint_name, PUBLISHED_VELOCITY_LIMITS.get(bare))
        return float(self.default_velocity_limit if limit is None else limit)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON view of every option."""
        return asdict(self)
