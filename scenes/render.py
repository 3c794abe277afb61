"""Pictures of scenes: MuJoCo offscreen renders (a matplotlib fallback) and SDF slices.

Rendering uses ``mujoco.Renderer``; on machines without a GPU set ``MUJOCO_GL=egl`` before MuJoCo
is imported (Mesa's software EGL works headless; the CLI does this). When no GL backend loads,
:func:`render_scene` draws top and side occupancy views with matplotlib instead and says why.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import torch

from controlmm.atomic import atomic_path
from scenes.scene import Scene

if TYPE_CHECKING:  # matplotlib is heavy: imported only when a picture is drawn
    from matplotlib.axes import Axes


def scene_bounds(scene: Scene, margin: float = 0.6) -> np.ndarray:
    """(2, 3) world box around the obstacles (every pose of their tracks) and the start pose."""
    m = scene.model
    data = mujoco.MjData(m)
    points = [np.array([scene.start.x, scene.start.y, 0.0]), np.array([scene.start.x, scene.start.y, 1.4])]
    times = sorted({0.0, *(float(t) for tr in scene.tracks.values() for t in tr.times)})
    for t in times:
        scene.set_time(data, t)
        mujoco.mj_kinematics(m, data)
        for g in scene.obstacle_geom_ids:
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
                continue
            centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            rot = data.geom_xmat[g].reshape(3, 3)
            world_centre = data.geom_xpos[g] + rot @ centre
            world_half = np.abs(rot) @ half
            points += [world_centre - world_half, world_centre + world_half]
    pts = np.stack(points)
    lo, hi = pts.min(0) - margin, pts.max(0) + margin
    if not scene.obstacle_geom_ids:  # an empty floor: show 4 m ahead of the start
        lo[:2] = np.minimum(lo[:2], [scene.start.x - 1.0, scene.start.y - 1.5])
        hi[:2] = np.maximum(hi[:2], [scene.start.x + 3.5, scene.start.y + 1.5])
    lo[2] = min(lo[2], 0.0)
    return np.stack([lo, hi])


def _posed_data(scene: Scene, t: float) -> mujoco.MjData:
    data = mujoco.MjData(scene.model)
    if scene.robot is not None:
        data.qpos[:] = scene.robot_start_qpos()
    scene.set_time(data, t)
    mujoco.mj_forward(scene.model, data)
    return data


def render_scene(
    scene: Scene, out: str | os.PathLike[str], width: int = 800, height: int = 600, t: float = 0.0
) -> str:
    """Write a PNG with a perspective and a top view of ``scene`` at time ``t``.

    Returns the backend used: ``"mujoco"`` or ``"matplotlib (...reason...)"`` when MuJoCo's
    renderer could not start.
    """
    try:
        images = _mujoco_views(scene, width, height, t)
    except Exception as exc:  # noqa: BLE001 - any GL failure means: fall back
        reason = (
            f"MuJoCo rendering failed with MUJOCO_GL={os.environ.get('MUJOCO_GL', '(unset)')}: "
            f"{type(exc).__name__}: {' '.join(str(exc).split())[:160]}"
        )
        _matplotlib_views(scene, out, t)
        return f"matplotlib ({reason})"
    import matplotlib  # heavy: loaded only when a picture is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(2 * width / 100, height / 100 + 0.5), dpi=100)
    for ax, image, title in zip(axes, images, ("perspective", "top view (X right, Y up)"), strict=True):
        ax.imshow(image)
        ax.set_title(title)
        ax.axis("off")
    fig.suptitle(_title(scene, t))
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return "mujoco"


def _title(scene: Scene, t: float) -> str:
    robot = f", robot {scene.robot}" if scene.robot else ""
    moving = f", t = {t:g} s" if scene.tracks else ""
    return f"scene '{scene.name}'{robot}{moving}: {len(scene.obstacle_geom_ids)} obstacle geoms"


def _mujoco_views(scene: Scene, width: int, height: int, t: float) -> list[np.ndarray]:
    m = scene.model
    data = _posed_data(scene, t)
    lo, hi = scene_bounds(scene)
    centre = (lo + hi) / 2
    extent = float(np.max(hi[:2] - lo[:2]))
    old = (m.vis.global_.offwidth, m.vis.global_.offheight, m.vis.global_.orthographic, m.vis.global_.fovy)
    m.vis.global_.offwidth, m.vis.global_.offheight = max(width, old[0]), max(height, old[1])
    try:
        renderer = mujoco.Renderer(m, height, width)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = (centre[0], centre[1], 0.5)
        cam.distance = 0.9 * extent + 1.5
        cam.azimuth = math.degrees(scene.start.yaw) + 25.0  # behind the start, looking ahead
        cam.elevation = -28.0
        renderer.update_scene(data, cam)
        perspective = renderer.render().copy()
        m.vis.global_.orthographic = 1  # fovy is then the view's height in metres
        m.vis.global_.fovy = float(max(hi[1] - lo[1], (hi[0] - lo[0]) * height / width))
        if hasattr(cam, "orthographic"):
            cam.orthographic = 1
        cam.lookat[:] = (centre[0], centre[1], 0.0)
        cam.distance = 20.0
        cam.azimuth, cam.elevation = 90.0, -90.0
        renderer.update_scene(data, cam)
        top = renderer.render().copy()
        renderer.close()
    finally:
        (m.vis.global_.offwidth, m.vis.global_.offheight, m.vis.global_.orthographic, m.vis.global_.fovy) = (
            old
        )
    return [perspective, top]


def occupancy_grid(
    scene: Scene, lo: np.ndarray, hi: np.ndarray, t: float, res: int = 140
) -> tuple[np.ndarray, ...]:
    """Scene SDF on a (res, res, max(20, res // 3)) grid over the box lo..hi at time t:
    (xs, ys, zs, values)."""
    sdf = scene.sdf()
    xs, ys = np.linspace(lo[0], hi[0], res), np.linspace(lo[1], hi[1], res)
    zs = np.linspace(max(lo[2], 0.0), hi[2], max(20, res // 3))
    grid = torch.as_tensor(np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), -1), dtype=torch.float32)
    with torch.no_grad():
        values = (
            sdf(grid.reshape(-1, 1, 3), torch.full((grid[..., 0].numel(),), t))
            .reshape(grid.shape[:-1])
            .numpy()
            if scene.obstacle_geom_ids
            else np.full(grid.shape[:-1], np.inf)
        )
    return xs, ys, zs, values


def _robot_points(scene: Scene, t: float) -> np.ndarray:
    if scene.robot is None:
        return np.zeros((0, 3))
    data = _posed_data(scene, t)
    return data.xpos[1:][
        np.isin(np.arange(1, scene.model.nbody), [scene.model.geom_bodyid[g] for g in scene.robot_geom_ids])
    ]


def _matplotlib_views(scene: Scene, out: str | os.PathLike[str], t: float) -> None:
    import matplotlib  # heavy: loaded only when a picture is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo, hi = scene_bounds(scene)
    xs, ys, zs, values = occupancy_grid(scene, lo, hi, t)
    robot = _robot_points(scene, t)
    fig, (top, side) = plt.subplots(1, 2, figsize=(13, 5.5))
    top.imshow(
        (values.min(axis=2) < 0).T,
        origin="lower",
        extent=(xs[0], xs[-1], ys[0], ys[-1]),
        cmap="Oranges",
        vmin=0,
        vmax=1.5,
    )
    top.set(title="top view (obstacles projected)", xlabel="x (m)", ylabel="y (m)", aspect="equal")
    side.imshow(
        (values.min(axis=1) < 0).T,
        origin="lower",
        extent=(xs[0], xs[-1], zs[0], zs[-1]),
        cmap="Oranges",
        vmin=0,
        vmax=1.5,
    )
    side.set(title="side view (obstacles projected along y)", xlabel="x (m)", ylabel="z (m)", aspect="equal")
    for ax, k in ((top, 1), (side, 2)):
        if len(robot):
            ax.scatter(robot[:, 0], robot[:, k], s=8, c="tab:blue", label=f"{scene.robot} bodies")
    _start_arrow(top, scene)
    top.legend(loc="upper right", fontsize=8)
    fig.suptitle(_title(scene, t))
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def _start_arrow(ax: Axes, scene: Scene) -> None:
    s = scene.start
    ax.annotate(
        "",
        xy=(s.x + 0.6 * math.cos(s.yaw), s.y + 0.6 * math.sin(s.yaw)),
        xytext=(s.x, s.y),
        arrowprops=dict(arrowstyle="->", color="tab:green", lw=2),
    )
    ax.plot([s.x], [s.y], "o", color="tab:green", label="start")


def plot_sdf_slice(
    scene: Scene,
    out: str | os.PathLike[str],
    height: float = 0.5,
    t: float = 0.0,
    y: float | None = None,
    res: int = 240,
) -> None:
    """Write a PNG of the scene SDF: a horizontal slice at z = ``height`` and a vertical slice
    at y = ``y`` (default: the start's y), zero level in black, 0.1 m contours."""
    import matplotlib  # heavy: loaded only when a picture is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm

    lo, hi = scene_bounds(scene)
    y_cut = scene.start.y if y is None else y
    sdf = scene.sdf()
    xs, ys = np.linspace(lo[0], hi[0], res), np.linspace(lo[1], hi[1], res)
    zs = np.linspace(0.0, max(hi[2], height + 0.3), res // 2)
    horiz = np.stack([*np.meshgrid(xs, ys, indexing="xy"), np.full((res, res), height)], -1)
    vert = np.stack(
        [
            np.meshgrid(xs, zs, indexing="xy")[0],
            np.full((len(zs), res), y_cut),
            np.meshgrid(xs, zs, indexing="xy")[1],
        ],
        -1,
    )
    with torch.no_grad():
        h_val = sdf(torch.as_tensor(horiz.reshape(-1, 3)), t).numpy().reshape(res, res)
        v_val = sdf(torch.as_tensor(vert.reshape(-1, 3)), t).numpy().reshape(len(zs), res)
    finite = np.concatenate([h_val[np.isfinite(h_val)], v_val[np.isfinite(v_val)]])
    vmax = float(np.clip(np.abs(finite).max() if len(finite) else 1.0, 0.05, 1.0))
    vmin = float(min(-0.05, finite.min() if len(finite) else -0.05))
    norm = TwoSlopeNorm(vcenter=0.0, vmin=vmin, vmax=vmax)
    fig, (a, b) = plt.subplots(1, 2, figsize=(14, 5.8), gridspec_kw={"width_ratios": [1, 1]})
    for ax, values, ext, title, xl, yl in (
        (a, h_val, (xs[0], xs[-1], ys[0], ys[-1]), f"horizontal slice z = {height:g} m", "x (m)", "y (m)"),
        (b, v_val, (xs[0], xs[-1], zs[0], zs[-1]), f"vertical slice y = {y_cut:g} m", "x (m)", "z (m)"),
    ):
        shown = np.where(np.isfinite(values), values, vmax)
        im = ax.imshow(shown, origin="lower", extent=ext, cmap="RdBu", norm=norm, aspect="equal")
        if np.isfinite(values).any():
            grid_x = np.linspace(ext[0], ext[1], values.shape[1])
            grid_y = np.linspace(ext[2], ext[3], values.shape[0])
            levels = np.arange(math.floor(vmin * 10) / 10, vmax + 1e-9, 0.1)
            ax.contour(grid_x, grid_y, shown, levels=levels, colors="k", linewidths=0.3, alpha=0.5)
            if (shown < 0).any() and (shown > 0).any():
                ax.contour(grid_x, grid_y, shown, levels=[0.0], colors="k", linewidths=1.5)
        ax.set(title=title, xlabel=xl, ylabel=yl)
    _start_arrow(a, scene)
    fig.colorbar(im, ax=[a, b], label="signed distance to obstacles (m), negative inside", shrink=0.85)
    moving = f", t = {t:g} s" if scene.tracks else ""
    fig.suptitle(f"SDF of scene '{scene.name}'{moving} (floor excluded; 0.1 m contours)")
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
