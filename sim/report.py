"""The check report: verdict, statistics, failures, per-frame arrays, JSON and a summary.

``report.json`` layout (format ``controlmm.sim.report/1``)::

    {"format", "passed", "num_frames", "fps", "duration_s",
     "max_penetration_m", "min_clearance_m", "floor_penetration_m", "max_self_collision_m",
     "self_collision_frames", "joint_limit_violations", "max_joint_limit_violation_rad",
     "joint_velocity_violations", "max_joint_velocity_ratio", "foot_sliding_m",
     "max_foot_slide_speed_mps", "floating_frames", "flight_frames",
     "error_count", "warning_count", "error_kinds",
     "residual_force": {"mean_ratio", "p95_ratio", "max_ratio", "max_N", "sustained_max_ratio"},
     "residual_moment": {"mean_m", "p95_m", "max_m", "sustained_max_m"}, "max_torque_ratio",
     "max_sustained_torque_ratio", "tracking": {...} | null, "physics": {...} | null,
     "per_body": {body: {...}},
     "failures": [{"kind", "frame_start", "frame_end", "robot_body", "obstacle_geom", "depth", "joint",
                   "severity"}],
     "frames": {name: [per-frame values]}, "feet", "joints", "config", "extra"}

Per-frame arrays use metres, radians and ratios as in their names; ``null`` marks a value
that was not measured (e.g. clearance when no obstacle was within the sensing distance).
``passed`` is true when no failure has ``severity == "error"``; warnings are reported too.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controlmm.atomic import write_text
from controlmm.errors import InputFileError
from sim.config import CheckConfig
from sim.dynamics import DynamicsResult
from sim.failures import Failure
from sim.kinematic import KinematicResult
from sim.physics import PhysicsResult
from sim.physics.result import physics_summary
from sim.tracking import TrackingResult

FORMAT = "controlmm.sim.report/1"
SUMMARY_FAILURES = 8


def json_number(x: Any, digits: int = 6) -> Any:
    """JSON-safe number: rounded float, None for None/NaN/inf."""
    if x is None:
        return None
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def json_array(a: np.ndarray, digits: int = 6) -> list:
    a = np.asarray(a)
    if a.dtype == bool:
        return a.astype(bool).tolist()
    return [json_number(v, digits) for v in a.tolist()] if a.ndim == 1 else [json_array(r, digits) for r in a]


@dataclass
class Report:
    """Outcome of :func:`sim.check_trajectory`.

    ``passed`` is True when no failure is an error (warnings are listed in ``failures`` with
    ``severity == "warning"``). Statistics use metres, radians and ratios
    as their names say; ``frames`` maps names to per-frame numpy arrays (see the module
    docstring); ``kinematic``/``dynamics``/``tracking`` keep the full in-memory results
    (None after :func:`load_report`). ``extra`` is free-form (e.g. feedback rounds).
    """

    passed: bool
    num_frames: int
    fps: float
    failures: list[Failure]
    stats: dict[str, Any]
    frames: dict[str, np.ndarray]
    feet: list[str]
    joints: list[str]
    config: CheckConfig
    extra: dict[str, Any] = field(default_factory=dict)
    kinematic: KinematicResult | None = None
    dynamics: DynamicsResult | None = None
    tracking: TrackingResult | None = None
    physics: PhysicsResult | None = None

    # The contract's named statistics, as attributes.
    @property
    def max_penetration_m(self) -> float:
        return float(self.stats["max_penetration_m"])

    @property
    def floor_penetration_m(self) -> float:
        return float(self.stats["floor_penetration_m"])

    @property
    def self_collision_frames(self) -> int:
        return int(self.stats["self_collision_frames"])

    @property
    def joint_limit_violations(self) -> int:
        return int(self.stats["joint_limit_violations"])

    @property
    def foot_sliding_m(self) -> float:
        return float(self.stats["foot_sliding_m"])

    @property
    def residual_force(self) -> dict[str, float]:
        return dict(self.stats["residual_force"])

    @property
    def duration_s(self) -> float:
        return self.num_frames / self.fps

    def failures_of(self, kind: str, severity: str | None = None) -> list[Failure]:
        """Failures of one kind (and one severity when given)."""
        return [f for f in self.failures if f.kind == kind and (severity is None or f.severity == severity)]

    @property
    def errors(self) -> list[Failure]:
        """The failures that make the report fail."""
        return [f for f in self.failures if f.is_error]

    @property
    def warnings(self) -> list[Failure]:
        """Failures reported as warnings only (brief dynamic exceedances by default)."""
        return [f for f in self.failures if not f.is_error]

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        stats = {
            k: (v if isinstance(v, (dict, list)) or v is None else json_number(v))
            for k, v in self.stats.items()
        }
        for key in ("residual_force", "residual_moment", "tracking"):
            part = stats.get(key)
            if isinstance(part, dict):
                stats[key] = {k: json_number(v) for k, v in part.items()}
        return {
            "format": FORMAT,
            "passed": bool(self.passed),
            "num_frames": int(self.num_frames),
            "fps": json_number(self.fps),
            "duration_s": json_number(self.duration_s),
            **stats,
            "failures": [f.to_dict() for f in self.failures],
            "frames": {k: json_array(v) for k, v in self.frames.items()},
            "feet": list(self.feet),
            "joints": list(self.joints),
            "config": self.config.to_dict(),
            "extra": self.extra,
        }

    def to_json(self, indent: int | None = 1) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``report.json`` atomically (temporary file + rename)."""
        write_text(path, self.to_json() + "\n")

    # --------------------------------------------------------------------- summary
    def summary(self, max_failures: int = SUMMARY_FAILURES) -> str:
        """A few human-readable lines: verdict, the main figures, the first failures."""
        s, c = self.stats, self.config
        verdict = "PASSED" if self.passed else "FAILED"
        n_err, n_warn = len(self.errors), len(self.warnings)
        lines = [
            f"{verdict}: {self.num_frames} frames at {self.fps:g} fps ({self.duration_s:.2f} s), "
            f"{n_err} error{'s' if n_err != 1 else ''}, {n_warn} warning{'s' if n_warn != 1 else ''}"
        ]
        clearance = s.get("min_clearance_m")
        clear_txt = f", min clearance {clearance * 1000:.1f} mm" if clearance is not None else ""
        lines.append(
            f"  contact: obstacle penetration {s['max_penetration_m'] * 1000:.1f} mm (tol "
            f"{c.obstacle_penetration_m * 1000:.1f}){clear_txt}; floor "
            f"{s['floor_penetration_m'] * 1000:.1f} mm (tol {c.floor_penetration_m * 1000:.1f}); "
            f"self-collision {s['self_collision_frames']} frames"
        )
        lines.append(
            f"  joints: {s['joint_limit_violations']} frames past limits "
            f"(max {s['max_joint_limit_violation_rad']:.4f} rad), "
            f"peak speed {s['max_joint_velocity_ratio'] * 100:.0f}% of limit; feet: slid "
            f"{s['foot_sliding_m'] * 1000:.1f} mm in stance (peak {s['max_foot_slide_speed_mps']:.2f} m/s); "
            f"floating {s['floating_frames']} frames, flight {s['flight_frames']}"
        )
        rf, rm = s.get("residual_force"), s.get("residual_moment")
        if rf is not None and rm is not None:
            lines.append(
                f"  dynamics: residual force mean {rf['mean_ratio'] * 100:.1f}% / max "
                f"{rf['max_ratio'] * 100:.1f}% of m g (warn {c.max_residual_force_ratio * 100:.0f}%), "
                f"sustained {rf['sustained_max_ratio'] * 100:.1f}% "
                f"(fail {c.max_sustained_residual_force_ratio * 100:.0f}%); "
                f"residual moment max {rm['max_m'] * 1000:.0f} mm "
                f"(warn {c.max_residual_moment_m * 1000:.0f}), "
                f"sustained {rm['sustained_max_m'] * 1000:.0f} mm "
                f"(fail {c.max_sustained_residual_moment_m * 1000:.0f}); "
                f"torque peak {s['max_torque_ratio'] * 100:.0f}% of limit, sustained "
                f"{s['max_sustained_torque_ratio'] * 100:.0f}% "
                f"(fail {c.max_sustained_torque_ratio * 100:.0f}%)"
            )
        tr = s.get("tracking")
        if tr:
            state = f"fell at {tr['time_up_s']:.2f} s" if tr["fell"] else "stayed up"
            lines.append(f"  PD tracking: {state}, joint error mean {tr['mean_joint_error_rad']:.3f} rad")
        ph = s.get("physics")
        if ph:
            lines.append(physics_summary(ph))
        for f in self.failures[:max_failures]:  # errors first
            lines.append(f"  - {f.describe(self.fps)}")
        if len(self.failures) > max_failures:
            lines.append(f"  ... and {len(self.failures) - max_failures} more (see report.json)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def load_report(path: str | os.PathLike[str]) -> Report:
    """Read a ``report.json`` written by :meth:`Report.save` (without the in-memory results)."""
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise InputFileError(f"report '{path}' does not exist") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise InputFileError(f"cannot read report '{path}': {exc}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputFileError(f"'{path}' is not a controlmm simulation report (format {FORMAT})")
    skip = {
        "format",
        "passed",
        "num_frames",
        "fps",
        "duration_s",
        "failures",
        "frames",
        "feet",
        "joints",
        "config",
        "extra",
    }
    stats = {k: v for k, v in data.items() if k not in skip}
    frames = {k: np.array([np.nan if v is None else v for v in vals]) for k, vals in data["frames"].items()}
    config = CheckConfig(**data["config"])
    failures = [Failure(**f) for f in data["failures"]]
    return Report(
        passed=bool(data["passed"]),
        num_frames=int(data["num_frames"]),
        fps=float(data["fps"]),
        failures=failures,
        stats=stats,
        frames=frames,
        feet=list(data["feet"]),
        joints=list(data["joints"]),
        config=config,
        extra=dict(data.get("extra") or {}),
    )
