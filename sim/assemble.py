"""A check's results assembled into a :class:`sim.report.Report`: verdict, statistics, arrays.

:func:`build_report` merges the failures of the kinematic, dynamics and tracking checks,
computes the report's named statistics (penetration, sliding, residual wrench, torque
ratios, per-body figures) and keeps the per-frame arrays the plot and the JSON file show.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.config import CheckConfig
from sim.dynamics import DynamicsResult
from sim.failures import sort_failures
from sim.kinematic import KinematicResult
from sim.physics import PhysicsResult
from sim.report import Report, json_number
from sim.tracking import TrackingResult
from sim.world import CheckWorld


def _stats(values: np.ndarray) -> tuple[float, float, float]:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 0.0, 0.0
    return float(v.mean()), float(np.percentile(v, 95)), float(v.max())


def build_report(
    world: CheckWorld,
    fps: float,
    config: CheckConfig,
    kin: KinematicResult,
    dyn: DynamicsResult | None = None,
    trk: TrackingResult | None = None,
    extra: dict[str, Any] | None = None,
    phys: PhysicsResult | None = None,
) -> Report:
    """Assemble a :class:`Report` from the kinematic, dynamics, tracking and physics results."""
    T = kin.num_frames
    failures = list(kin.failures)
    for part in (dyn, trk, phys):
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
        "physics": None,
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
    if phys is not None:
        stats["physics"] = phys.to_dict()
        frames.update(phys.frames())
    per_body = {}
    for i, b in enumerate(world.robot_bodies):
        values = {
            "obstacle_penetration_m": float(kin.body_obstacle_penetration[:, i].max(initial=0.0)),
            "floor_penetration_m": float(kin.body_floor_penetration[:, i].max(initial=0.0)),
            "self_collision_m": float(kin.body_self_collision[:, i].max(initial=0.0)),
        }
        if any(v > 0 for v in values.values()):
            per_body[world.body_name(b)] = {k: json_number(v) for k, v in values.items()}
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
        physics=phys,
    )
