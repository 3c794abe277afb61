"""Checked robot trajectories: input validation, finite-difference velocities, substeps.

A trajectory is ``qpos (T, nq)`` in MuJoCo order (free joint xyz + quaternion wxyz, then the
joints) sampled at ``fps``. Velocities come from ``mj_differentiatePos`` (quaternion-aware;
the free joint's angular velocity is in the root body frame, as MuJoCo defines ``qvel``).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from controlmm.errors import ControlMMError, ShapeError
from sim.world import CheckWorld

MIN_FPS = 1.0
MAX_FPS = 1000.0


def _describe_nq(world: CheckWorld) -> str:
    return (
        f"nq={world.nq} (free joint xyz + quaternion wxyz, then {world.nq - 7} joint positions)"
        if world.nq >= 7
        else f"nq={world.nq}"
    )


def validate_qpos(world: CheckWorld, qpos: object, fps: object) -> tuple[np.ndarray, float]:
    """Check ``qpos`` and ``fps`` against the model; return float64 qpos with unit quaternions.

    Raises:
        ShapeError: wrong shape, NaN/inf, a zero root quaternion (one-line message).
        ControlMMError: fps not a finite number in [1, 1000].
    """
    try:
        rate = float(fps)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ControlMMError(f"fps must be a number in [{MIN_FPS:g}, {MAX_FPS:g}]; got {fps!r}") from None
    if not (math.isfinite(rate) and MIN_FPS <= rate <= MAX_FPS):
        raise ControlMMError(f"fps must be a number in [{MIN_FPS:g}, {MAX_FPS:g}]; got {fps!r}")
    try:
        q = np.array(qpos, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError(f"qpos must be a numeric (T, nq) array; got {type(qpos).__name__}") from None
    if q.ndim == 1 and q.size == world.nq:
        q = q[None]
    if q.ndim != 2 or q.shape[1] != world.nq:
        raise ShapeError(f"qpos has shape {q.shape}; the model expects (T, {_describe_nq(world)})")
    if q.shape[0] == 0:
        raise ShapeError("qpos has no frames; expected at least 1")
    bad = ~np.isfinite(q)
    if bad.any():
        t, c = np.argwhere(bad)[0]
        raise ShapeError(f"qpos holds NaN/inf (first at frame {t}, column {c}); every value must be finite")
    a = world.root_qpos_adr + 3
    norm = np.linalg.norm(q[:, a : a + 4], axis=1)
    if (norm < 1e-6).any():
        t = int(np.argmax(norm < 1e-6))
        raise ShapeError(f"qpos frame {t} has a zero root quaternion (columns {a}..{a + 3}, wxyz)")
    q[:, a : a + 4] /= norm[:, None]
    return q, rate


def half_step_velocities(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> np.ndarray:
    """Velocities between consecutive frames, (T-1, nv): ``v[k]`` takes frame k to frame k+1."""
    out = np.zeros((max(qpos.shape[0] - 1, 0), model.nv))
    dt = 1.0 / fps
    for k in range(out.shape[0]):
        mujoco.mj_differentiatePos(model, out[k], dt, qpos[k], qpos[k + 1])
    return out


def velocities_and_accelerations(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Finite-difference ``qvel`` and ``qacc`` at every frame, each (T, nv), plus the half steps.

    ``qvel[t]`` is the mean of the half-step velocities around frame t (one-sided at the
    ends); ``qacc[t]`` is their difference times fps (central second difference), copied from
    the neighbour at the first and last frame. A single frame has zero velocity/acceleration.
    """
    half = half_step_velocities(model, qpos, fps)
    T = qpos.shape[0]
    qvel = np.zeros((T, model.nv))
    qacc = np.zeros((T, model.nv))
    if T >= 2:
        qvel[0] = half[0]
        qvel[-1] = half[-1]
        qvel[1:-1] = 0.5 * (half[:-1] + half[1:])
    if T >= 3:
        qacc[1:-1] = (half[1:] - half[:-1]) * fps
        qacc[0] = qacc[1]
        qacc[-1] = qacc[-2]
    return qvel, qacc, half


def interpolate(
    model: mujoco.MjModel, qpos: np.ndarray, half: np.ndarray, fps: float, substeps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Insert ``substeps`` poses between consecutive frames (constant velocity on the manifold).

    Returns:
        dense qpos ``((T-1)*(substeps+1)+1, nq)`` and, per dense pose, the index of the frame
        it is pooled into (the nearest original frame).
    """
    T = qpos.shape[0]
    if substeps <= 0 or T < 2:
        return qpos, np.arange(T)
    n = substeps + 1
    dense = np.empty(((T - 1) * n + 1, model.nq))
    owner = np.empty(dense.shape[0], dtype=np.int64)
    for k in range(T - 1):
        for s in range(n):
            q = qpos[k].copy()
            if s:
                mujoco.mj_integratePos(model, q, half[k], s / (n * fps))
            dense[k * n + s] = q
            owner[k * n + s] = k if s * 2 < n else k + 1
    dense[-1] = qpos[-1]
    owner[-1] = T - 1
    return dense, owner
