"""Pictures of a plan: the path against the obstacles, and the clearance of every round.

* :func:`plot_top_view` - world top view: obstacle footprints (:func:`scenes.footprint.footprints`
  at the heights the body reaches), the robot's pelvis and feet paths, the human hands, the control
  targets and where the joints ended up, the start pose.
* :func:`plot_clearance` - per frame and per round: the robot's smallest distance to an obstacle
  (negative = penetration) and the lowest robot point above the floor, with the tolerances.
"""

from __future__ import annotations

import math
import os

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.motion.skeleton import JOINT_NAMES
from scenes.footprint import footprints
from scenes.render import scene_bounds


def _pyplot():
    import matplotlib  # only for plots; the Agg backend is chosen before pyplot loads

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_top_view(result, path: str | os.PathLike[str], dpi: int = 110) -> None:
    """Write the top view PNG of a :class:`~controlmm.pipeline.plan.PlanResult` (atomically)."""
    plt = _pyplot()
    from matplotlib.collections import PolyCollection  # with pyplot: only for plots

    scene, traj, motion = result.scene, result.trajectory, result.motion
    names, pos, _ = traj.body_poses()  # (T, B, 3) world
    world_joints = result.transform.to_world(motion.joints.astype(np.float64))  # (T, 22, 3)
    lo, hi = scene_bounds(scene)
    lo[:2] = np.minimum(lo[:2], pos[..., :2].reshape(-1, 2).min(0) - 0.3)
    hi[:2] = np.maximum(hi[:2], pos[..., :2].reshape(-1, 2).max(0) + 0.3)
    hi[2] = max(hi[2], float(pos[..., 2].max()) + 0.1)
    fig, ax = plt.subplots(figsize=(9, 6.5))
    polygons = footprints(scene, 0.0, (0.0, hi[2]))  # obstacles at the heights the body reaches
    if polygons:
        ax.add_collection(PolyCollection(polygons, facecolors="tab:orange", edgecolors="none", alpha=0.45))
    if scene.moving_geom_ids:
        ax.text(0.01, 0.01, "moving obstacles drawn at t = 0", transform=ax.transAxes, fontsize=8)
    root = pos[:, 0]  # the floating base (G1, H1: the pelvis)
    ax.plot(root[:, 0], root[:, 1], color="tab:blue", lw=2, label=f"{traj.robot} {names[0]}")
    for side, colour in (("left", "tab:green"), ("right", "tab:red")):
        foot = [
            i for i, n in enumerate(names) if side in n and ("ankle_roll" in n or n.endswith("ankle_link"))
        ]
        if foot:
            p = pos[:, foot[-1]]
            ax.plot(p[:, 0], p[:, 1], color=colour, lw=1, alpha=0.7, label=f"{side} foot")
        wrist = world_joints[:, JOINT_NAMES.index(f"{side}_wrist")]
        ax.plot(
            wrist[:, 0], wrist[:, 1], color=colour, lw=1, ls=":", alpha=0.7, label=f"{side} wrist (human)"
        )
    if result.spec is not None:
        targets = result.spec.human_positions(result.transform)
        tw = result.transform.to_world(targets.astype(np.float64))
        for c, target in zip(result.spec.constraints, tw, strict=True):
            got = world_joints[min(c.frame, len(world_joints) - 1), c.joint]
            ax.plot([target[0]], [target[1]], "x", color="black", ms=9, mew=2)
            ax.plot([got[0]], [got[1]], "o", mfc="none", color="black", ms=8)
            ax.annotate(
                f"{JOINT_NAMES[c.joint]} @{c.frame}",
                target[:2],
                textcoords="offset points",
                xytext=(5, 5),
                fontsize=7,
            )
        ax.plot([], [], "x", color="black", label="target")
        ax.plot([], [], "o", mfc="none", color="black", label="achieved")
    s = scene.start
    ax.annotate(
        "",
        xy=(s.x + 0.5 * math.cos(s.yaw), s.y + 0.5 * math.sin(s.yaw)),
        xytext=(s.x, s.y),
        arrowprops=dict(arrowstyle="->", color="tab:purple", lw=2),
    )
    ax.set(
        xlim=(lo[0], hi[0]),
        ylim=(lo[1], hi[1]),
        xlabel="x (m)",
        ylabel="y (m)",
        aspect="equal",
        title=f"{scene.name}: {'PASSED' if result.passed else 'FAILED'} (round {result.best}) - "
        f"{result.text[:70]}",
    )
    ax.legend(loc="upper left", fontsize=7, ncol=2)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)


def plot_clearance(result, path: str | os.PathLike[str], dpi: int = 110) -> None:
    """Write the per-frame clearance PNG of every round of a plan (atomically)."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, constrained_layout=True)
    config = result.final.report.config
    for r in result.rounds:
        f = r.report.frames
        t = f["time_s"]
        clearance = np.asarray(f["clearance_m"], dtype=float)  # signed; NaN beyond the sensing distance
        style = dict(lw=2 if r.index == result.best else 1, alpha=1.0 if r.index == result.best else 0.6)
        label = f"round {r.index} ({'pass' if r.passed else 'fail'})"
        top.plot(t, clearance, label=label, **style)
        bottom.plot(t, f["lowest_height_m"], label=label, **style)
    top.axhline(-config.obstacle_penetration_m, color="red", ls="--", lw=1, label="penetration tolerance")
    top.axhline(0.0, color="black", lw=0.5)
    top.set(
        ylabel="obstacle clearance (m)",
        title=f"{result.scene.name}: robot distance to obstacles "
        "(negative = penetration; gaps = nothing near)",
    )
    bottom.axhline(-config.floor_penetration_m, color="red", ls="--", lw=1, label="floor tolerance")
    bottom.axhline(0.0, color="black", lw=0.5)
    bottom.set(xlabel="time (s)", ylabel="lowest point above floor (m)")
    for ax in (top, bottom):
        ax.legend(fontsize=7, loc="upper right")
    if not result.scene.obstacle_geom_ids:
        top.text(0.5, 0.5, "no obstacles in this scene", transform=top.transAxes, ha="center")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
