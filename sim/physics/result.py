"""What the physics execution check measured (:class:`PhysicsResult`) and its verdict.

Per trajectory frame (T frames; frames after an early stop are NaN / False):

=======================  ===================================================================
array                    meaning
=======================  ===================================================================
root_error_m             distance of the simulated root from the reference root
root_height_m            simulated root height
tilt_error_deg           angle between the simulated and the reference root's up axes
joint_error_rad          RMS over the actuated joints of simulated - reference angle
effector_error_m         (T, E) error of each end effector (feet, hands) relative to the root,
                         in the root's frame (a drift of the whole robot does not count here)
foot_contact             (T, F) the foot touches the floor or an obstacle
other_contact            a robot geom other than the feet touches the floor or an obstacle
torque_ratio             (T, J) peak |actuator torque| / limit over the steps into the frame
simulated                the frame was reached by the simulation
=======================  ===================================================================

The verdict: a ``tracking_fall`` failure from the first frame where the root is below
``fall_height_ratio`` x its reference height (at most the first frame's: a reference floating
up does not make a robot that stays on its feet count as fallen) or its up axis is more than
``max_tilt_error_deg`` from the reference's (depth: metres the root dropped below its
reference); ``tracking_error`` failures for spans of at least ``min_error_span_s`` where the root
is more than ``max_root_error_m`` from its reference or an end effector more than
``max_body_error_m`` (depth: the worst error, metres; ``robot_body`` names the body). Spans
after a fall are not reported again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim.failures import Failure, from_mask, runs
from sim.physics.config import PhysicsConfig


@dataclass
class PhysicsResult:
    """Outcome of :func:`sim.track` (see the module docstring for the per-frame arrays).

    Attributes:
        passed: no failure.
        fps: trajectory rate; timestep: simulation step (s).
        fell: whether the robot fell; fall_frame: first frame of the fall (None if it stayed up).
        failures: ``tracking_fall`` and ``tracking_error`` failures (all errors).
        feet, effectors, joints: names of the columns of the (T, F), (T, E), (T, J) arrays.
        actuators: names of the columns of ``ctrl``; root_qpos_adr: qpos address of the root.
        qpos, qvel: (S+1, nq), (S+1, nv) simulated states at every simulation step.
        ctrl: (S, nu) the control input applied at each ``mj_step``.
        mocap_pos, mocap_quat: (S, nmocap, 3 / 4) mocap poses set before each step, or None
            when nothing moves.
        model_xml: the executed model as one MJCF string (``sim.track`` needs the world's MjSpec).
        stats: summary figures (see :meth:`to_dict`).
        config: the settings used.
    """

    passed: bool
    fps: float
    timestep: float
    fell: bool
    fall_frame: int | None
    failures: list[Failure]
    root_error_m: np.ndarray
    root_height_m: np.ndarray
    tilt_error_deg: np.ndarray
    joint_error_rad: np.ndarray
    effector_error_m: np.ndarray
    foot_contact: np.ndarray
    other_contact: np.ndarray
    torque_ratio: np.ndarray
    simulated: np.ndarray
    feet: list[str]
    effectors: list[str]
    joints: list[str]
    actuators: list[str]
    root_qpos_adr: int
    qpos: np.ndarray
    qvel: np.ndarray
    ctrl: np.ndarray
    mocap_pos: np.ndarray | None
    mocap_quat: np.ndarray | None
    model_xml: str
    config: PhysicsConfig
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.root_error_m.shape[0])

    @property
    def steps(self) -> int:
        """Simulation steps taken (rows of ``ctrl``)."""
        return int(self.ctrl.shape[0])

    def frames(self) -> dict[str, np.ndarray]:
        """Per-frame arrays for the report (``physics_*`` names; 1-D each)."""
        out: dict[str, np.ndarray] = {
            "physics_root_error_m": self.root_error_m,
            "physics_root_height_m": self.root_height_m,
            "physics_tilt_error_deg": self.tilt_error_deg,
            "physics_joint_error_rad": self.joint_error_rad,
            "physics_max_effector_error_m": _row_max(self.effector_error_m),
            "physics_other_contact": self.other_contact,
            "physics_max_torque_ratio": _row_max(self.torque_ratio),
            "physics_simulated": self.simulated,
        }
        for i, name in enumerate(self.feet):
            out[f"physics_foot_contact:{name}"] = self.foot_contact[:, i]
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``physics`` entry of ``report.json``: verdict and figures (no per-frame arrays)."""
        return {"passed": bool(self.passed), **self.stats, "config": self.config.to_dict()}

    def summary(self) -> str:
        """One line: verdict, time up, errors, torque use, speed."""
        return physics_summary(self.to_dict())


def physics_summary(stats: dict[str, Any]) -> str:
    """The summary line of a ``physics`` report entry (:meth:`PhysicsResult.to_dict`)."""
    s = stats
    state = f"fell at {s['time_up_s']:.2f} s" if s["fell"] else "stayed up"
    return (
        f"  physics: {'PASSED' if s['passed'] else 'FAILED'}, {state}; root error mean "
        f"{s['mean_root_error_m'] * 100:.1f} cm (max {s['max_root_error_m'] * 100:.1f}), "
        f"joint error mean {s['mean_joint_error_rad']:.3f} rad; "
        f"torque peak {s['max_torque_ratio'] * 100:.0f}% of limit; {s['realtime_factor']:.2f}x real time"
    )


def _row_max(values: np.ndarray) -> np.ndarray:
    if values.ndim == 1:
        return values
    if values.shape[1] == 0:
        return np.zeros(values.shape[0])
    out = np.full(values.shape[0], np.nan)
    ok = ~np.all(np.isnan(values), axis=1)
    out[ok] = np.nanmax(values[ok], axis=1)
    return out


def fall_frame(
    root_height: np.ndarray, ref_height: np.ndarray, tilt_error_deg: np.ndarray, config: PhysicsConfig
) -> int | None:
    """First frame where the robot has fallen (root too low or tilted too far), else None."""
    with np.errstate(invalid="ignore"):
        down = (root_height < config.fall_height_ratio * ref_height) | (
            tilt_error_deg > config.max_tilt_error_deg
        )
    hit = np.flatnonzero(down)
    return int(hit[0]) if hit.size else None


def verdict(
    result_fall: int | None,
    root_error: np.ndarray,
    root_drop: np.ndarray,
    effector_error: np.ndarray,
    root_body: str,
    effectors: list[str],
    fps: float,
    config: PhysicsConfig,
) -> list[Failure]:
    """The failures of a run (see the module docstring).

    Args:
        result_fall: first fallen frame or None.
        root_error: (T,) m; root_drop: (T,) reference height - simulated height (m).
        effector_error: (T, E) m; root_body / effectors: body names.
    """
    T = root_error.shape[0]
    end = T if result_fall is None else result_fall
    min_frames = max(1, int(round(config.min_error_span_s * fps)))
    failures: list[Failure] = []
    if result_fall is not None:
        drop = (
            float(np.nanmax(root_drop[result_fall:])) if np.isfinite(root_drop[result_fall:]).any() else 0.0
        )
        failures.append(Failure("tracking_fall", result_fall, T - 1, root_body, None, max(drop, 0.0)))

    def spans(mask: np.ndarray, values: np.ndarray, body: str) -> list[Failure]:
        mask = np.asarray(mask, dtype=bool).copy()
        mask[end:] = False
        for a, b in runs(mask):
            if b - a + 1 < min_frames:
                mask[a : b + 1] = False
        return from_mask("tracking_error", mask, values, robot_body=body)

    with np.errstate(invalid="ignore"):
        failures += spans(root_error > config.max_root_error_m, root_error, root_body)
        for i, name in enumerate(effectors):
            failures += spans(effector_error[:, i] > config.max_body_error_m, effector_error[:, i], name)
    return failures
