"""Robot trajectories for the simulation-check tests, built from real robot poses.

Poses start from the Menagerie keyframes (G1 ``stand``; H1 ``home`` values from its
scene.xml), are edited joint by joint, blended smoothly, and "planted": the root is moved so
the feet keep the standing pose's ground contact, as a retargeter would.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim.geometry import support_heights
from sim.world import CheckWorld

H1_HOME = {
    "left_hip_pitch": -0.4,
    "left_knee": 0.8,
    "left_ankle": -0.4,
    "right_hip_pitch": -0.4,
    "right_knee": 0.8,
    "right_ankle": -0.4,
}


def adr(model: mujoco.MjModel, joint: str) -> int:
    return int(model.jnt_qposadr[model.joint(joint).id])


def with_joints(model: mujoco.MjModel, q: np.ndarray, **values: float) -> np.ndarray:
    out = np.array(q, dtype=np.float64)
    for name, v in values.items():
        out[adr(model, name)] = v
    return out


def smooth_blend(qa: np.ndarray, qb: np.ndarray, n: int) -> np.ndarray:
    """n poses from qa to qb (inclusive) with a cosine ease; quaternions normalised."""
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n))
    out = (1 - s)[:, None] * qa + s[:, None] * qb
    out[:, 3:7] /= np.linalg.norm(out[:, 3:7], axis=1, keepdims=True)
    return out


def hold(q: np.ndarray, n: int) -> np.ndarray:
    return np.tile(q, (n, 1))


def feet_reference(world: CheckWorld, q: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean horizontal position of the feet's geoms and their lowest height, for pose q."""
    m = world.model
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    geoms = np.concatenate([f.geoms for f in world.feet])
    xy = d.geom_xpos[geoms, :2].mean(axis=0)
    low = support_heights(
        m,
        geoms,
        d.geom_xpos[geoms][None],
        d.geom_xmat[geoms][None],
        np.zeros((1, 3)),
        np.array([[0.0, 0.0, 1.0]]),
        world.hull_vertices,
    )
    return xy, float(np.nanmin(low))


def plant(world: CheckWorld, frames: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Shift each frame's root so its feet sit where they are in ``reference`` (xy and height)."""
    ref_xy, ref_low = feet_reference(world, reference)
    out = np.array(frames, dtype=np.float64)
    a = world.root_qpos_adr
    for t in range(out.shape[0]):
        xy, low = feet_reference(world, out[t])
        out[t, a : a + 2] += ref_xy - xy
        out[t, a + 2] += ref_low - low
    return out


def rotate_about(q: np.ndarray, axis_point: np.ndarray, angle: float, root_adr: int = 0) -> np.ndarray:
    """Rotate the whole robot about a horizontal y-axis through ``axis_point`` by ``angle``."""
    out = np.array(q, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    p = out[root_adr : root_adr + 3] - axis_point
    out[root_adr : root_adr + 3] = axis_point + rot @ p
    dq = np.array([np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0])
    res = np.zeros(4)
    mujoco.mju_mulQuat(res, dq, out[root_adr + 3 : root_adr + 7])
    out[root_adr + 3 : root_adr + 7] = res
    return out


# ------------------------------------------------------------------ cached worlds and poses
from functools import cache  # noqa: E402

from sim.world import make_world  # noqa: E402
from sim.worlds import Obstacle, robot_world, standing_qpos  # noqa: E402

FPS = 50.0


@cache
def g1_world() -> CheckWorld:
    """G1 on a floor with a shelf, a post, a low step and a mocap ball (parked far away)."""
    model = robot_world(
        "g1",
        [
            Obstacle("shelf", "box", (0.25, 0.12, 0.05), (0.55, 0.09, 1.06)),
            Obstacle("post", "cylinder", (0.05, 0.6), (-0.6, 0.4, 0.6)),
            Obstacle("step", "box", (0.2, 0.3, 0.05), (1.2, -0.8, 0.05)),
            Obstacle("ball", "sphere", (0.1,), (0.0, 3.0, 0.5), mocap=True),
        ],
    )
    return make_world(model)


@cache
def h1_world() -> CheckWorld:
    return make_world(robot_world("h1"))


def g1_stand() -> np.ndarray:
    return standing_qpos(g1_world().model)


def h1_stand() -> np.ndarray:
    w = h1_world()
    q = with_joints(w.model, standing_qpos(w.model), **H1_HOME)
    return plant(w, q[None], standing_qpos(w.model))[0]


def g1_squat_pose() -> np.ndarray:
    m = g1_world().model
    return with_joints(
        m,
        g1_stand(),
        **{
            f"{s}_{j}": v
            for s in ("left", "right")
            for j, v in (("hip_pitch_joint", -0.8), ("knee_joint", 1.6), ("ankle_pitch_joint", -0.8))
        },
    )


def g1_squat() -> np.ndarray:
    """Stand, squat down over 1 s, hold, rise: 130 frames at 50 fps, feet planted."""
    q0, sq = g1_stand(), g1_squat_pose()
    frames = np.concatenate(
        [hold(q0, 10), smooth_blend(q0, sq, 50), hold(sq, 10), smooth_blend(sq, q0, 50), hold(q0, 10)]
    )
    return plant(g1_world(), frames, q0)


@cache
def g1_bare() -> CheckWorld:
    """G1 on an empty floor."""
    return make_world(robot_world("g1"))


def lean_about_toes(world: CheckWorld, q0: np.ndarray, degrees: float, n: int) -> np.ndarray:
    """n frames rotating the standing robot forward about its toe spheres' axis (toes stay put)."""
    m = world.model
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    mujoco.mj_kinematics(m, d)
    geoms = np.concatenate([f.geoms for f in world.feet])
    toes = geoms[d.geom_xpos[geoms, 0] > d.geom_xpos[geoms, 0].mean()]
    pivot = np.array([d.geom_xpos[toes, 0].mean(), 0.0, d.geom_xpos[toes, 2].mean()])
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n))
    return np.stack([rotate_about(q0, pivot, np.deg2rad(degrees) * a, world.root_qpos_adr) for a in s])
