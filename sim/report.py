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
     "max_sustained_torque_ratio", "tracking": {...} | null, "per_body": {body: {...}},
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
from sim.failures import Failure, sort_failures
from sim.kinematic import KinematicResult
from sim.tracking import TrackingResult
from sim.world import CheckWorld

FORMAT = "controlmm.sim.report/1"
SUMMARY_FAILURES = 8


def _num(x: Any, digits: int = 6) -> Any:
    """JSON-safe number: rounded float, None for None/NaN/inf."""
    if x is None:
        return None
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    x = float(x)
    return round(x, digits) if math.isfinite(x) else None


def _arr(a: np.ndarray, digits: int = 6) -> list:
    a = np.asarray(a)
    if a.dtype == bool:
        return a.astype(bool).tolist()
    return [_num(v, digits) for v in a.tolist()] if a.ndim == 1 else [_arr(r, digits) for r in a]


def _stats(values: np.ndarray) -> tuple[float, float, float]:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 0.0, 0.0
    return float(v.mean()), float(np.percentile(v, 95)), float(v.max())


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
            k: (v if isinstance(v, (dict, list)) or v is None else _num(v)) for k, v in self.stats.items()
        }
        for key in ("residual_force", "residual_moment", "tracking"):
            if isinstance(stats.get(key), dict):
                stats[key] = {k: _num(v) for k, v in stats[key].items()}
        return {
            "format": FORMAT,
            "passed": bool(self.passed),
            "num_frames": int(self.num_frames),
            "fps": _num(self.fps),
            "duration_s": _num(self.duration_s),
            **stats,
            "failures": [f.to_dict() for f in self.failures],
            "frames": {k: _arr(v) for k, v in self.frames.items()},
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
            f"{c.obstacle_penetration_m * 1000:.1f}){clear_txt}; floor {s['floor_penetration_m'] * 1000:.1f} mm "
            f"(tol {c.floor_penetration_m * 1000:.1f}); self-collision {s['self_collision_frames']} frames"
        )
        lines.append(
            f"  joints: {s['joint_limit_violations']} frames past limits (max {s['max_joint_limit_violation_rad']:.4f} "
            f"rad), peak speed {s['max_joint_velocity_ratio'] * 100:.0f}% of limit; feet: slid "
            f"{s['foot_sliding_m'] * 1000:.1f} mm in stance (peak {s['max_foot_slide_speed_mps']:.2f} m/s); "
            f"floating {s['floating_frames']} frames, flight {s['flight_frames']}"
        )
        rf, rm = s.get("residual_force"), s.get("residual_moment")
        if rf is not None and rm is not None:
            lines.append(
                f"  dynamics: residual force mean {rf['mean_ratio'] * 100:.1f}% / max "
                f"{rf['max_ratio'] * 100:.1f}% of m g (warn {c.max_residual_force_ratio * 100:.0f}%), sustained "
                f"{rf['sustained_max_ratio'] * 100:.1f}% (fail {c.max_sustained_residual_force_ratio * 100:.0f}%); "
                f"residual moment max {rm['max_m'] * 1000:.0f} mm (warn {c.max_residual_moment_m * 1000:.0f}), "
                f"sustained {rm['sustained_max_m'] * 1000:.0f} mm (fail {c.max_sustained_residual_moment_m * 1000:.0f}); "
                f"torque peak {s['max_torque_ratio'] * 100:.0f}% of limit, sustained "
                f"{s['max_sustained_torque_ratio'] * 100:.0f}% (fail {c.max_sustained_torque_ratio * 100:.0f}%)"
            )
        tr = s.get("tracking")
        if tr:
            state = f"fell at {tr['time_up_s']:.2f} s" if tr["fell"] else "stayed up"
            lines.append(f"  PD tracking: {state}, joint error mean {tr['mean_joint_error_rad']:.3f} rad")
        for f in self.failures[:max_failures]:  # errors first
            lines.append(f"  - {f.describe(self.fps)}")
        if len(self.failures) > max_failures:
            lines.append(f"  ... and {len(self.failures) - max_failures} more (see report.json)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def build_report(
    world: CheckWorld,
    fps: float,
    config: CheckConfig,
    kin: KinematicResult,
    dyn: DynamicsResult | None = None,
    trk: TrackingResult | None = None,
    extra: dict[str, Any] | None = None,
) -> Report:
    """Assemble a :class:`Report` from the kinematic, dynamics and tracking results."""
    T = kin.num_frames
    failures = list(kin.failures)
    for part in (dyn, trk):
        failures += part.failures if part is not None else []
    failures = sort_failures(failures)
    errors = [f for f in failures if f.is_error]
    tol = config
    violated = kin.joint_limit_violation > tol.joint_limit_tol_rad
    stance_slide = np.where(kin.foot_stance, kin.foot_slide, 0.0)
    stats: dict[str, Any] = {
        "max_penetration_m": float(kin.obstacle_penetration.max(initial=0.0)),
        "min_clearance_m": (float(np.nanmin(kin.clearance)) if np.isfinite(kin.clearance).any() else None),
        "floor_penetration_m": float(kin.floor_penetration.max(initial=0.0)),
        "max_self_collision_m": float(kin.self_collision.max(initial=0.0)),
        "self_collision_frames": int((kin.self_collision > tol.self_collision_m).sum()),
        "joint_limit_violations": int(violated.any(axis=1).sum()) if violated.size else 0,
        "max_joint_limit_violation_rad": float(kin.joint_limit_violation.max(initial=0.0)),
        "joint_velocity_violations": int((kin.joint_velocity_ratio > 1.0).any(axis=1).sum())
        if kin.joint_velocity_ratio.size
        else 0,
        "max_joint_velocity_ratio": float(kin.joint_velocity_ratio.max(initial=0.0)),
        "foot_sliding_m": float(stance_slide.sum()),
        "max_foot_slide_speed_mps": float(stance_slide.max(initial=0.0) * fps),
        "floating_frames": int(kin.floating.sum()),
        "flight_frames": int(kin.flight.sum()),
        "error_count": len(errors),
        "warning_count": len(failures) - len(errors),
        "error_kinds": sorted({f.kind for f in errors}),
        "residual_force": None,
        "residual_moment": None,
        "max_torque_ratio": None,
        "max_sustained_torque_ratio": None,
        "tracking": None,
    }
    frames: dict[str, np.ndarray] = {
        "time_s": np.arange(T) / fps,
        "obstacle_penetration_m": kin.obstacle_penetration,
        "clearance_m": kin.clearance,
        "floor_penetration_m": kin.floor_penetration,
        "lowest_height_m": kin.lowest_height,
        "self_collision_m": kin.self_collision,
        "joint_limit_margin_rad": kin.joint_limit_margin,
        "max_joint_velocity_ratio": (
            kin.joint_velocity_ratio.max(axis=1) if kin.joint_velocity_ratio.size else np.zeros(T)
        ),
        "supported": kin.supported,
        "floating": kin.floating,
        "flight": kin.flight,
    }
    feet = [f.name for f in world.feet]
    for i, name in enumerate(feet):
        frames[f"foot_height_m:{name}"] = kin.foot_height[:, i]
        frames[f"foot_slide_m:{name}"] = kin.foot_slide[:, i]
        frames[f"foot_stance:{name}"] = kin.foot_stance[:, i]
    if dyn is not None:
        mean, p95, peak = _stats(dyn.residual_force_ratio)
        stats["residual_force"] = {
            "mean_ratio": mean,
            "p95_ratio": p95,
            "max_ratio": peak,
            "max_N": peak * world.mass * float(np.linalg.norm(world.model.opt.gravity)),
            "sustained_max_ratio": float(dyn.sustained_force_ratio.max(initial=0.0)),
        }
        mean, p95, peak = _stats(dyn.residual_moment_m)
        stats["residual_moment"] = {
            "mean_m": mean,
            "p95_m": p95,
            "max_m": peak,
            "sustained_max_m": float(dyn.sustained_moment_m.max(initial=0.0)),
        }
        stats["max_torque_ratio"] = float(dyn.torque_ratio.max(initial=0.0))
        stats["max_sustained_torque_ratio"] = float(dyn.sustained_torque_ratio.max(initial=0.0))
        frames["residual_force_ratio"] = dyn.residual_force_ratio
        frames["residual_moment_m"] = dyn.residual_moment_m
        frames["max_torque_ratio"] = dyn.torque_ratio.max(axis=1) if dyn.torque_ratio.size else np.zeros(T)
        frames["sustained_residual_force_ratio"] = dyn.sustained_force_ratio
        frames["sustained_residual_moment_m"] = dyn.sustained_moment_m
        frames["max_sustained_torque_ratio"] = (
            dyn.sustained_torque_ratio.max(axis=1) if dyn.sustained_torque_ratio.size else np.zeros(T)
        )
    if trk is not None:
        stats["tracking"] = {
            "fell": trk.fell,
            "fall_frame": trk.fall_frame,
            "time_up_s": trk.time_up_s,
            "mean_joint_error_rad": float(trk.joint_error.mean()),
            "max_joint_error_rad": float(trk.joint_error.max()),
            "max_root_error_m": float(trk.root_error.max()),
        }
        frames["tracking_joint_error_rad"] = trk.joint_error
        frames["tracking_root_height_m"] = trk.root_height
    per_body = {}
    for i, b in enumerate(world.robot_bodies):
        values = {
            "obstacle_penetration_m": float(kin.body_obstacle_penetration[:, i].max(initial=0.0)),
            "floor_penetration_m": float(kin.body_floor_penetration[:, i].max(initial=0.0)),
            "self_collision_m": float(kin.body_self_collision[:, i].max(initial=0.0)),
        }
        if any(v > 0 for v in values.values()):
            per_body[world.body_name(b)] = {k: _num(v) for k, v in values.items()}
    stats["per_body"] = per_body
    return Report(
        passed=not errors,
        num_frames=T,
        fps=fps,
        failures=failures,
        stats=stats,
        frames=frames,
        feet=feet,
        joints=list(world.joints.names),
        config=config,
        extra=dict(extra or {}),
        kinematic=kin,
        dynamics=dyn,
        tracking=trk,
    )


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
