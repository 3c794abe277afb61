"""Settings of the physics execution check (:class:`PhysicsConfig`).

Three groups: the predictive controller (samples, horizon, spline knots, noise, rates), the
weights of its tracking cost, and the verdict (what counts as a fall or a tracking-error
span). Units: seconds, metres, radians, degrees where the name says so. Every default is
explained in ``docs/simulation-checks.md`` (section "Physics execution").
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from controlmm.errors import ControlMMError

_INTEGERS = ("samples", "flight_samples", "knots", "plan_substeps", "threads", "seed", "retries")


@dataclass(frozen=True)
class PhysicsConfig:
    """Options of :func:`sim.track`.

    Controller (predictive sampling over spline knots, ``sim.physics.sampler``):

    Attributes:
        samples: rollouts per planning step (the first one is the previous best plan).
        flight_samples: rollouts per planning step around the reference's flight phases (jumps,
            running strides: frames the kinematic check found unsupported and ballistic), from
            ``flight_margin_s`` before such a phase to ``flight_margin_s`` after it: a take-off and
            a landing need a broader search than walking does (never fewer than ``samples``).
        flight_margin_s: see ``flight_samples``.
        horizon_s: length of each rollout (s).
        knots: spline knots over the horizon (linear interpolation between them).
        replan_s: time between two planning steps (s); the plan is applied in between.
        plan_substeps: simulation steps per rollout step (the rollouts use a timestep this
            many times the model's; 1 = the model's own).
        threads: threads of the persistent rollout pool.
        seed: noise seed (the run is deterministic for a seed and a thread count).
        memory_s: time constant (s) with which the warm-started plan returns to the nominal
            targets: an offset that no later plan confirms fades, so directions the cost hardly
            sees (an arm's pose) do not drift in a random walk from one plan to the next.
        sigma_foot_m: noise of a foot's position relative to the root, per knot (m).
        sigma_foot_rad: noise of a foot's orientation relative to the root, per knot (rad).
        sigma_joint_rad: noise of the other actuators' targets (waist, arms), per knot (rad).
        wrist_noise: also perturb actuators whose joint name contains "wrist" (off: a hand's
            orientation does not help balance, and their 5 N m motors are the weakest).
        retries: times the controller may back up after a fall: it restores the simulation to
            the planning step ``retry_back_s`` x (the retry's number) before the fall and plans
            on from there with a fresh noise stream and ``flight_samples`` rollouts per step
            until ``flight_margin_s`` after the fall's step (0: a fall is final).
        retry_back_s: see ``retries``.
        retry_lost: also back up where the root is more than ``max_root_error_m`` from its
            reference (the start of a ``tracking_error`` span), not only after a fall.

    Cost weights (per rollout step, summed over the horizon, ``sim.physics.cost``):

    Attributes:
        w_root_height: (root height error / m)^2.
        w_root_xy: (horizontal root position error / m)^2.
        w_root_rot: 1 - cos^2(root orientation error / 2) (0 aligned, 1 upside down).
        w_joint: mean squared joint angle error (rad^2).
        w_com: (horizontal centre-of-mass error / m)^2.
        w_com_vel: (centre-of-mass velocity error / (m/s))^2.
        w_feet: sum over feet of (position error / m)^2.
        w_effort: mean squared deviation of the targets from the nominal ones (rad^2).
        terminal: extra weight of the last rollout step (as a multiple of one step).

    Verdict (``sim.physics.verdict``):

    Attributes:
        fall_height_ratio: fallen when the root is below this fraction of its reference height
            (at most the first frame's reference height).
        max_tilt_error_deg: fallen when the root's up axis is this far from the reference's.
        max_root_error_m: a ``tracking_error`` span where the root is this far from its reference.
        max_body_error_m: a ``tracking_error`` span where a foot or hand (relative to the
            root) is this far from its reference.
        min_error_span_s: shorter exceedances are not reported.
        start_penetration_m: the first frame may not put a robot geom deeper than this into
            the floor or an obstacle (bad input: the robot would start inside the scene).
        after_fall_s: the simulation stops this long after a fall.
    """

    samples: int = 64
    flight_samples: int = 128
    flight_margin_s: float = 0.5
    horizon_s: float = 0.5
    knots: int = 4
    replan_s: float = 0.04
    plan_substeps: int = 5
    threads: int = 2
    seed: int = 0
    memory_s: float = 0.4
    sigma_foot_m: float = 0.03
    sigma_foot_rad: float = 0.08
    sigma_joint_rad: float = 0.03
    wrist_noise: bool = False
    retries: int = 3
    retry_back_s: float = 1.0
    retry_lost: bool = True
    w_root_height: float = 100.0
    w_root_xy: float = 10.0
    w_root_rot: float = 30.0
    w_joint: float = 5.0
    w_com: float = 100.0
    w_com_vel: float = 3.0
    w_feet: float = 30.0
    w_effort: float = 1.0
    terminal: float = 3.0
    fall_height_ratio: float = 0.6
    max_tilt_error_deg: float = 60.0
    max_root_error_m: float = 0.25
    max_body_error_m: float = 0.25
    min_error_span_s: float = 0.1
    start_penetration_m: float = 0.01
    after_fall_s: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool):
                continue
            if f.name in _INTEGERS:
                if not isinstance(value, int):
                    raise ControlMMError(f"PhysicsConfig.{f.name} must be a whole number; got {value!r}")
            elif not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ControlMMError(f"PhysicsConfig.{f.name} must be a finite number >= 0; got {value!r}")
        for name, low in (
            ("samples", 2),
            ("flight_samples", 2),
            ("knots", 2),
            ("plan_substeps", 1),
            ("threads", 1),
            ("seed", 0),
            ("retries", 0),
        ):
            if getattr(self, name) < low:
                raise ControlMMError(
                    f"PhysicsConfig.{name} must be at least {low}; got {getattr(self, name)}"
                )
        if self.horizon_s <= 0 or self.replan_s <= 0 or self.memory_s <= 0:
            raise ControlMMError(
                "PhysicsConfig.horizon_s, replan_s and memory_s must be > 0; "
                f"got {self.horizon_s}, {self.replan_s}, {self.memory_s}"
            )
        if self.replan_s > self.horizon_s:
            raise ControlMMError(
                f"PhysicsConfig.replan_s ({self.replan_s}) must not exceed horizon_s ({self.horizon_s})"
            )
        if not 0 < self.fall_height_ratio < 1:
            raise ControlMMError(
                f"PhysicsConfig.fall_height_ratio must be in (0, 1); got {self.fall_height_ratio!r}"
            )
        if not 0 < self.max_tilt_error_deg <= 180:
            raise ControlMMError(
                f"PhysicsConfig.max_tilt_error_deg must be in (0, 180]; got {self.max_tilt_error_deg!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON view of every option."""
        return asdict(self)
