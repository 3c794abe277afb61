"""Quality figures of a robot trajectory, measured with MuJoCo itself (``mj_kinematics``).

Everything here re-reads the qpos through MuJoCo, independently of the solver's own
kinematics: keypoint errors against the scaled human, joint-limit violations, floor
penetration of the feet's collision geometry (exact lowest point per geom type), stance-foot
sliding and smoothness (joint velocity and jerk).

Foot contact: a foot touches the floor when the lowest point of its collision geoms is at
most ``CONTACT_HEIGHT`` (5 mm) above it in two consecutive frames; a stance is a run of
such frame pairs. The feet roll (heel strike, flat, toe-off): the ankle moves while the
geom on the floor stays put, so slip is measured at the contact: per frame pair, the
horizontal displacement of the foot's collision geom that is down in both frames and moved
least (as :mod:`sim.kinematic` does). Per stance: *sliding* = the largest horizontal
distance of a down geom from where it touched down, while it stays down (mm), *path* = the
foot body's horizontal path length (mm, includes the roll); *skate* = mean contact slide per
contact frame (PhysDiff's skate, mm).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from retarget.robot_model import RobotModel

KEYPOINT_GROUPS: dict[str, tuple[str, ...]] = {
    "feet": ("left_ankle", "right_ankle", "left_foot", "right_foot"),
    "hands": ("left_wrist", "right_wrist"),
    "pelvis": ("pelvis",),
    "head": ("head",),
}
"""Keypoint groups reported separately (only mapped joints count)."""

CONTACT_HEIGHT = 0.005
"""A foot is in contact when its lowest collision point is at most this high (m)."""


@dataclass
class Replay:
    """MuJoCo kinematics of a qpos trajectory.

    Attributes:
        xpos: (T, nbody, 3) body positions; xquat: (T, nbody, 4) wxyz; xmat: (T, nbody, 3, 3).
        geom_xpos: (T, ngeom, 3); geom_xmat: (T, ngeom, 3, 3).
    """

    xpos: np.ndarray
    xquat: np.ndarray
    xmat: np.ndarray
    geom_xpos: np.ndarray
    geom_xmat: np.ndarray


def replay(model: mujoco.MjModel, qpos: np.ndarray) -> Replay:
    """Run ``mj_kinematics`` on every frame of ``qpos`` (T, nq)."""
    data = mujoco.MjData(model)
    t = len(qpos)
    xpos = np.empty((t, model.nbody, 3))
    xquat = np.empty((t, model.nbody, 4))
    xmat = np.empty((t, model.nbody, 9))
    gpos = np.empty((t, model.ngeom, 3))
    gmat = np.empty((t, model.ngeom, 9))
    for i in range(t):
        data.qpos[:] = qpos[i]
        mujoco.mj_kinematics(model, data)
        xpos[i], xquat[i], xmat[i] = data.xpos, data.xquat, data.xmat
        gpos[i], gmat[i] = data.geom_xpos, data.geom_xmat
    return Replay(xpos, xquat, xmat.reshape(t, -1, 3, 3), gpos, gmat.reshape(t, -1, 3, 3))


_HULLS: dict[bytes, np.ndarray] = {}


def replay_keypoints(robot: RobotModel, rep: Replay) -> np.ndarray:
    """(T, K, 3) world positions of the robot's keypoints in the frames of ``rep``."""
    bodies = np.array([robot.tree.node_body[n] for n in robot.nodes])
    return rep.xpos[:, bodies] + np.einsum("tkij,kj->tki", rep.xmat[:, bodies], robot.offsets)


def foot_steps(robot: RobotModel, rep: Replay, side: str, sole: bool = True) -> np.ndarray:
    """(T - 1,) horizontal step (m) between consecutive frames of ``rep`` of the ``side``
    foot's slowest sole point (its floor points: a foot pivoting on its heel or toe does not
    move there), or of its body origin (``sole=False``)."""
    foot = robot.feet[side]
    body = int(robot.tree.node_body[foot.node])
    local = foot.points if sole else np.zeros((1, 3))
    points = rep.xpos[:, body, None, :] + np.einsum("tij,pj->tpi", rep.xmat[:, body], local)
    return np.linalg.norm(np.diff(points[..., :2], axis=0), axis=2).min(axis=1)


def hull_vertices(verts: np.ndarray) -> np.ndarray:
    """The vertices (H, 3) of the convex hull of a mesh's vertices (V, 3), cached by content.

    A linear function (a height) is smallest on a hull vertex, so the lowest point of a
    mesh needs only these (a G1 ankle mesh: ~8,500 vertices, a few hundred on its hull).
    """
    key = hashlib.sha1(np.ascontiguousarray(verts).tobytes()).digest()
    if key not in _HULLS:
        try:
            _HULLS[key] = np.ascontiguousarray(verts[ConvexHull(verts).vertices])
        except Exception:  # noqa: BLE001 - a flat or degenerate mesh: keep every vertex
            _HULLS[key] = np.ascontiguousarray(verts)
    return _HULLS[key]


def geom_lowest_z(model: mujoco.MjModel, rep: Replay, geoms: list[int] | tuple[int, ...]) -> np.ndarray:
    """Exact lowest world z (T, G) of collision geoms (sphere, capsule, cylinder, box, ellipsoid, mesh)."""
    t = mujoco.mjtGeom
    out = np.empty((rep.geom_xpos.shape[0], len(geoms)))
    for i, g in enumerate(geoms):
        z = rep.geom_xpos[:, g, 2]
        r2 = rep.geom_xmat[:, g, 2, :]  # world z component of the geom's axes
        size = model.geom_size[g]
        kind = int(model.geom_type[g])
        if kind == int(t.mjGEOM_SPHERE):
            low = z - size[0]
        elif kind == int(t.mjGEOM_CAPSULE):
            low = z - np.abs(r2[:, 2]) * size[1] - size[0]
        elif kind == int(t.mjGEOM_CYLINDER):
            low = z - np.abs(r2[:, 2]) * size[1] - size[0] * np.sqrt(np.clip(1 - r2[:, 2] ** 2, 0, None))
        elif kind == int(t.mjGEOM_BOX):
            low = z - np.abs(r2) @ size[:3]
        elif kind == int(t.mjGEOM_ELLIPSOID):
            low = z - np.sqrt(((r2 * size[:3]) ** 2).sum(axis=1))
        elif kind == int(t.mjGEOM_MESH):
            mid = model.geom_dataid[g]
            verts = model.mesh_vert[
                model.mesh_vertadr[mid] : model.mesh_vertadr[mid] + model.mesh_vertnum[mid]
            ]
            low = z + (r2 @ hull_vertices(verts).T).min(axis=1)
        else:
            low = np.full(len(z), np.inf)
        out[:, i] = low
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(int)))
    return list(zip(edges[::2], edges[1::2], strict=True))


def trajectory_metrics(
    robot: RobotModel,
    qpos: np.ndarray,
    fps: float,
    human_world: np.ndarray | None = None,
    human_fps: float | None = None,
    rep: Replay | None = None,
) -> dict:
    """Quality figures of ``qpos`` (T, nq) at ``fps`` for a :class:`retarget.robot_model.RobotModel`.

    ``human_world``: the scaled human (T_h, 22, 3) in the world at ``human_fps``; keypoint
    errors compare the robot's mapped points with it (linearly interpolated to ``fps``).
    Lengths in mm, angles in rad. ``rep``: a :func:`replay` of ``qpos`` already computed.
    """
    model = robot.model
    rep = rep if rep is not None else replay(model, qpos)
    out: dict = {"frames": int(len(qpos)), "fps": float(fps)}
    # Keypoints: body position + body rotation @ offset (node frames are body frames here).
    bodies = np.array([robot.tree.node_body[n] for n in robot.nodes])
    kp = rep.xpos[:, bodies] + np.einsum("tkij,kj->tki", rep.xmat[:, bodies], robot.offsets)
    if human_world is not None:
        times = np.arange(len(qpos)) / fps
        src = np.arange(len(human_world)) / (human_fps or fps)
        flat = human_world.reshape(len(human_world), -1)
        ref = np.stack([np.interp(times, src, flat[:, c]) for c in range(flat.shape[1])], -1)
        ref = ref.reshape(len(times), 22, 3)[:, robot.joints]
        err = np.linalg.norm(kp - ref, axis=-1) * 1000.0
        groups = {**KEYPOINT_GROUPS, "all": tuple(robot.keypoint_names)}
        out["keypoint_error_mm"] = {}
        for name, joints in groups.items():
            idx = [robot.keypoint_names.index(j) for j in joints if j in robot.keypoint_names]
            if idx:
                e = err[:, idx]
                out["keypoint_error_mm"][name] = {
                    "mean": round(float(e.mean()), 1),
                    "max": round(float(e.max()), 1),
                }
    # Joint limits (exact comparison with the model's ranges).
    tree = robot.tree
    q = qpos[:, 7:]
    over = np.maximum(q - tree.upper, 0) + np.maximum(tree.lower - q, 0)
    out["joint_limit_violations"] = int(np.count_nonzero(over > 0))
    out["joint_limit_max_overshoot_rad"] = float(over.max()) if over.size else 0.0
    # Floor and feet.
    lowest = {}
    for side in ("left", "right"):
        f = robot.feet[side]
        lowest[side] = geom_lowest_z(model, rep, f.geoms).min(axis=1)
    low_all = np.minimum(lowest["left"], lowest["right"])
    out["floor_penetration_max_mm"] = round(float(max(0.0, -low_all.min()) * 1000.0), 3)
    drift, path, steps = [], [], []
    for side in ("left", "right"):
        f = robot.feet[side]
        body = robot.tree.node_body[f.node]
        geom_low = geom_lowest_z(model, rep, f.geoms)  # (T, G)
        down = (geom_low[:-1] <= CONTACT_HEIGHT) & (geom_low[1:] <= CONTACT_HEIGHT)
        geom_step = np.linalg.norm(np.diff(rep.geom_xpos[:, list(f.geoms), :2], axis=0), axis=2)
        slide = np.where(down, geom_step, np.inf).min(axis=1) * 1000.0  # (T-1,) contact slide
        contact = np.isfinite(slide)
        xy = rep.xpos[:, body, :2]
        body_step = np.linalg.norm(np.diff(xy, axis=0), axis=1) * 1000.0
        for s, e in _runs(contact):  # contact pairs s..e-1 cover frames s..e
            worst = 0.0  # each geom, from where it touched down, while it stays down
            for i, g in enumerate(f.geoms):
                for a, b in _runs(down[s:e, i]):
                    p = rep.geom_xpos[s + a : s + b + 1, g, :2]
                    worst = max(worst, float(np.linalg.norm(p - p[0], axis=1).max()))
            drift.append(worst * 1000.0)
            path.append(float(body_step[s:e].sum()))
            steps.append(slide[s:e])
    out["stances"] = len(drift)

    def stat(v: list[float]) -> dict:
        return {
            "mean": round(float(np.mean(v)), 2) if v else 0.0,
            "max": round(float(np.max(v)), 2) if v else 0.0,
        }

    out["foot_sliding_mm_per_stance"] = stat(drift)
    out["foot_path_mm_per_stance"] = stat(path)
    out["foot_skate_mm_per_frame"] = round(float(np.concatenate(steps).mean()), 3) if steps else 0.0
    # Smoothness.
    if len(q) > 3:
        vel = np.diff(q, axis=0) * fps
        jerk = np.diff(q, n=3, axis=0) * fps**3
        root_jerk = np.diff(qpos[:, :3], n=3, axis=0) * fps**3
        out["joint_velocity_max_rad_s"] = round(float(np.abs(vel).max()), 3)
        out["joint_jerk_rms_rad_s3"] = round(float(np.sqrt(np.mean(jerk**2))), 2)
        out["root_jerk_rms_m_s3"] = round(float(np.sqrt(np.mean(root_jerk**2))), 3)
    return out
