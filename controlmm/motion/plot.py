"""Looking at motions: a still PNG (skeleton snapshots + top view) and animations.

Plots use world axes (X forward, Y left, Z up; see :mod:`controlmm.frames`) so that human
motions and robot scenes are drawn the same way.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.errors import ControlMMError
from controlmm.frames import human_to_world_axes
from controlmm.motion.container import Motion
from controlmm.motion.skeleton import KINEMATIC_CHAINS
from controlmm.video import write_video

_CHAIN_COLORS = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd")
IMAGE_FORMATS = (".png",)


def _figure(size=(10, 5)):
    import matplotlib  # only for plots; the Agg backend is chosen before pyplot loads

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt.figure(figsize=size, dpi=100)


def _limits(world: np.ndarray) -> tuple[np.ndarray, float]:
    lo, hi = world.reshape(-1, 3).min(0), world.reshape(-1, 3).max(0)
    centre = (lo + hi) / 2
    half = max((hi - lo)[:2].max() / 2, 1.0) + 0.2
    return centre, half


def _setup_3d(ax, world: np.ndarray) -> None:
    centre, half = _limits(world)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(0, max(2.0, world[..., 2].max() + 0.2))
    ax.set_box_aspect((1, 1, max(2.0, world[..., 2].max() + 0.2) / (2 * half)))
    ax.set_xlabel("X fwd (m)")
    ax.set_ylabel("Y left (m)")
    ax.set_zlabel("Z up (m)")
    ax.view_init(elev=20, azim=-60)


def _draw_skeleton(ax, pose: np.ndarray, alpha: float = 1.0, lw: float = 2.0) -> list:
    artists = []
    for chain, color in zip(KINEMATIC_CHAINS, _CHAIN_COLORS, strict=True):
        pts = pose[list(chain)]
        (line,) = ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color=color, alpha=alpha, lw=lw)
        artists.append(line)
    return artists


def _draw_top_view(ax, world: np.ndarray, title: str = "top view") -> None:
    ax.plot(world[:, 0, 0], world[:, 0, 1], "k-", lw=2, label="pelvis")
    for j, name, style in (
        (10, "left foot", "b."),
        (11, "right foot", "r."),
        (20, "left wrist", "c-"),
        (21, "right wrist", "m-"),
    ):
        ax.plot(world[:, j, 0], world[:, j, 1], style, ms=2, lw=0.8, alpha=0.7, label=name)
    ax.plot(world[0, 0, 0], world[0, 0, 1], "go", label="start")
    ax.plot(world[-1, 0, 0], world[-1, 0, 1], "rs", label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("X fwd (m)")
    ax.set_ylabel("Y left (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def plot_motion(motion: Motion, path: str | Path, snapshots: int = 6) -> None:
    """Write a PNG: skeleton snapshots over time (3-D) and a top-view trajectory plot."""
    path = Path(path)
    if path.suffix.lower() not in IMAGE_FORMATS:
        raise ControlMMError(f"unknown image format '{path.suffix}'; allowed: .png")
    world = human_to_world_axes(motion.joints.astype(np.float64))
    fig = _figure((12, 5.5))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    _setup_3d(ax3, world)
    idx = np.linspace(0, motion.num_frames - 1, min(snapshots, motion.num_frames)).round().astype(int)
    for k, f in enumerate(idx):
        _draw_skeleton(ax3, world[f], alpha=0.25 + 0.75 * (k + 1) / len(idx), lw=1.5)
    ax3.plot(world[:, 0, 0], world[:, 0, 1], np.zeros(len(world)), "k--", lw=1)
    title = motion.text or "motion"
    ax3.set_title(f"{title[:60]}\n{motion.num_frames} frames, {motion.seconds:.1f} s", fontsize=9)
    _draw_top_view(fig.add_subplot(1, 2, 2), world)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    import matplotlib.pyplot as plt  # only for plots (_figure chose the backend)

    plt.close(fig)


def render_motion_frames(motion: Motion, size: tuple[int, int] = (640, 480)) -> Iterator[np.ndarray]:
    """Yield RGB frames (H, W, 3) uint8 of a 3-D stick-figure animation with a root trail."""
    import matplotlib.pyplot as plt  # only for plots

    world = human_to_world_axes(motion.joints.astype(np.float64))
    fig = _figure((size[0] / 100, size[1] / 100))
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    _setup_3d(ax, world)
    ax.set_title(motion.text[:70] or "motion", fontsize=9)
    lines = _draw_skeleton(ax, world[0])
    (trail,) = ax.plot([], [], [], "k--", lw=1)
    label = ax.text2D(0.02, 0.95, "", transform=ax.transAxes, fontsize=8)
    try:
        for f in range(motion.num_frames):
            for line, chain in zip(lines, KINEMATIC_CHAINS, strict=True):
                pts = world[f, list(chain)]
                line.set_data_3d(pts[:, 0], pts[:, 1], pts[:, 2])
            trail.set_data_3d(world[: f + 1, 0, 0], world[: f + 1, 0, 1], np.zeros(f + 1))
            label.set_text(f"t = {f / motion.fps:5.2f} s  frame {f}")
            fig.canvas.draw()
            yield np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    finally:
        plt.close(fig)


def animate_motion(motion: Motion, path: str | Path, size: tuple[int, int] = (640, 480)) -> int:
    """Write an ``.mp4`` or ``.gif`` stick-figure animation; returns the number of frames."""
    return write_video(path, render_motion_frames(motion, size), fps=motion.fps)


def plot_or_animate(motion: Motion, path: str | Path) -> None:
    """PNG -> still plot; MP4/GIF -> animation; anything else is a one-line error."""
    suffix = Path(path).suffix.lower()
    if suffix in IMAGE_FORMATS:
        plot_motion(motion, path)
    elif suffix in (".mp4", ".gif"):
        animate_motion(motion, path)
    else:
        raise ControlMMError(
            f"unknown output format '{Path(path).suffix or path}'; allowed: .png, .gif, .mp4"
        )
