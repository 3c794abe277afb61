"""Per-frame plot of a check report (PNG): contact, feet, dynamics, limits.

Panels share the time axis; failing frame ranges are shaded red in the panel of their kind,
thresholds are dashed lines.
"""

from __future__ import annotations

import os

import numpy as np

from controlmm.atomic import atomic_path
from sim.report import Report

_PANEL_OF = {
    "obstacle_penetration": 0,
    "floor_penetration": 0,
    "self_collision": 0,
    "foot_sliding": 1,
    "floating": 1,
    "residual_force": 2,
    "residual_moment": 2,
    "torque_limit": 3,
    "joint_limit": 3,
    "joint_velocity": 3,
    "joint_coupling": 3,
    "tracking_fall": 2,
}


def plot_report(
    report: Report, path: str | os.PathLike[str], title: str | None = None, dpi: int = 110
) -> None:
    """Write the per-frame plot of ``report`` to ``path`` (PNG, atomically)."""
    import matplotlib  # heavy: loaded only when a plot is drawn

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    f, c = report.frames, report.config
    t = f["time_s"]
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True, constrained_layout=True)
    verdict = "PASSED" if report.passed else f"FAILED ({len(report.failures)} failures)"
    fig.suptitle(title or f"Simulation check: {verdict}", fontsize=12)

    ax = axes[0]
    mm = 1000.0
    if np.isfinite(f["clearance_m"]).any():
        ax.plot(t, f["clearance_m"] * mm, color="tab:blue", label="obstacle clearance (min signed distance)")
    ax.plot(t, -f["obstacle_penetration_m"] * mm, color="tab:red", label="- obstacle penetration")
    ax.plot(t, -f["floor_penetration_m"] * mm, color="tab:brown", label="- floor penetration")
    ax.plot(t, -f["self_collision_m"] * mm, color="tab:purple", label="- self-collision depth")
    ax.axhline(-c.obstacle_penetration_m * mm, color="tab:red", ls="--", lw=0.8)
    ax.axhline(-c.floor_penetration_m * mm, color="tab:brown", ls=":", lw=0.8)
    ax.axhline(0.0, color="black", lw=0.5)
    ax.set_ylabel("distance [mm]")
    ax.set_title("clearance and penetration (negative = inside)", fontsize=9, loc="left")

    ax = axes[1]
    colors = ["tab:green", "tab:orange", "tab:cyan", "tab:olive"]
    for i, name in enumerate(report.feet):
        col = colors[i % len(colors)]
        h = f.get(f"foot_height_m:{name}")
        if h is not None and np.isfinite(h).any():
            ax.plot(t, h * mm, color=col, label=f"{name} height")
        slide = f[f"foot_slide_m:{name}"] * report.fps
        stance = f[f"foot_stance:{name}"].astype(bool)
        ax.plot(
            t, np.where(stance, slide, np.nan) * 100, color=col, ls="--", label=f"{name} stance slide [cm/s]"
        )
    ax.axhline(c.max_foot_slide_speed * 100, color="tab:red", ls="--", lw=0.8)
    ax.axhline(c.stance_height_m * mm, color="gray", ls=":", lw=0.8)
    floating = f["floating"].astype(bool)
    if floating.any():
        ax.fill_between(
            t,
            0,
            1,
            where=floating,
            transform=ax.get_xaxis_transform(),
            color="tab:red",
            alpha=0.12,
            label="floating",
        )
    flight = f["flight"].astype(bool)
    if flight.any():
        ax.fill_between(
            t,
            0,
            1,
            where=flight,
            transform=ax.get_xaxis_transform(),
            color="tab:blue",
            alpha=0.1,
            label="flight",
        )
    ax.set_ylabel("mm  |  cm/s")
    ax.set_title("feet: height above floor, stance sliding speed", fontsize=9, loc="left")

    ax = axes[2]
    if "residual_force_ratio" in f:
        ax.plot(t, f["residual_force_ratio"] * 100, color="tab:red", label="residual force [% m g]")
        ax.plot(t, f["residual_moment_m"] * mm, color="tab:purple", label="residual moment / m g [mm]")
        ax.axhline(c.max_residual_force_ratio * 100, color="tab:red", ls="--", lw=0.8)
        ax.axhline(c.max_residual_moment_m * mm, color="tab:purple", ls=":", lw=0.8)
    else:
        ax.text(0.5, 0.5, "dynamics check off", transform=ax.transAxes, ha="center", va="center")
    if "tracking_root_height_m" in f:
        ax2 = ax.twinx()
        ax2.plot(t, f["tracking_root_height_m"], color="gray", lw=0.8, label="PD replay root height [m]")
        ax2.set_ylabel("root height [m]")
    ax.set_ylabel("% m g  |  mm")
    ax.set_title("dynamic feasibility: non-physical root wrench", fontsize=9, loc="left")

    ax = axes[3]
    ax.plot(t, f["joint_limit_margin_rad"], color="tab:blue", label="min joint-limit margin [rad]")
    ax.plot(t, f["max_joint_velocity_ratio"], color="tab:orange", label="max |velocity| / limit")
    if "max_torque_ratio" in f:
        ax.plot(t, f["max_torque_ratio"], color="tab:red", label="max |torque| / limit")
    ax.axhline(1.0, color="tab:red", ls="--", lw=0.8)
    ax.axhline(0.0, color="black", lw=0.5)
    ax.set_ylabel("rad  |  ratio")
    ax.set_xlabel("time [s]")
    ax.set_title("limits", fontsize=9, loc="left")

    dt = 0.5 / report.fps
    for failure in report.failures:
        panel = axes[_PANEL_OF.get(failure.kind, 0)]
        panel.axvspan(
            t[failure.frame_start] - dt, t[failure.frame_end] + dt, color="tab:red", alpha=0.15, lw=0
        )
    for ax in axes:
        ax.grid(alpha=0.3)
        handles, _ = ax.get_legend_handles_labels()
        if handles:
            ax.legend(fontsize=7, loc="upper right", ncol=2)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
