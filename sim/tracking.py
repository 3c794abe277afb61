"""Optional stronger check: track the trajectory with stiff joint PD servos in physics.

The robot starts in the first frame's pose and velocity; every ``mj_step`` each hinge or
slide joint gets ``kp (q* - q) + kd (qd* - qd)`` (clipped to its torque limit) towards the
trajectory linearly interpolated to the simulation time. The floating base is free and
there is no balance controller, so this is open-loop PD replay: a stiff replay that stays up
is strong evidence, a fall says the motion needs a feedback policy (or is infeasible).
A replay of a G1 squat (20 fps targets interpolated to the 500 Hz step, free root) with the
Menagerie G1 gains (kp 500) tracked within 0.0055 rad mean error; BeyondMimic's policy-level
gains (meant for a learned policy) fell.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.config import CheckConfig
from sim.failures import Failure
from sim.world import CheckWorld


@dataclass
class TrackingResult:
    """Per-frame outcome of the PD-tracking replay (sampled at the trajectory's frames).

    Attributes:
        joint_error: (T,) RMS joint-angle error (rad) between simulation and target.
        root_error: (T,) root position error (m).
        root_height: (T,) simulated root height (m).
        fell: the root dropped below ``fall_height_ratio`` x the target root height.
        fall_frame: first frame of the fall (None if it never fell).
        time_up_s: seconds the robot stayed up.
        failures: one ``tracking_fall`` failure when it fell.
    """

    joint_error: np.ndarray
    root_error: np.ndarray
    root_height: np.ndarray
    fell: bool
    fall_frame: int | None
    time_up_s: float
    failures: list[Failure] = field(default_factory=list)


def _tracking_model(world: CheckWorld) -> mujoco.MjModel:
    m = copy.deepcopy(world.model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)  # torques come from qfrc_applied
    return m


def tracking_check(
    world: CheckWorld, qpos: np.ndarray, qvel: np.ndarray, half: np.ndarray, fps: float, config: CheckConfig
) -> TrackingResult:
    """Replay ``qpos`` (T, nq) at ``fps`` with PD servos in MuJoCo physics (``mj_step``)."""
    m = world.derived(("tracking",), lambda: _tracking_model(world))
    d = mujoco.MjData(m)
    J = world.joints
    limit = np.where(np.isfinite(J.torque_limit), J.torque_limit, np.inf)
    T = qpos.shape[0]
    dt = float(m.opt.timestep)
    steps_per_frame = max(int(round(1.0 / (fps * dt))), 1)
    mocap = world.mocap_poses(np.arange(T) / fps)

    d.qpos[:] = qpos[0]
    d.qvel[:] = qvel[0]
    mujoco.mj_forward(m, d)
    z0 = world.root_qpos_adr + 2
    joint_err = np.zeros(T)
    root_err = np.zeros(T)
    height = np.zeros(T)
    fall: int | None = None
    for t in range(T):
        err = d.qpos[J.qpos_adr] - qpos[t, J.qpos_adr]
        joint_err[t] = float(np.sqrt(np.mean(err**2))) if err.size else 0.0
        root = slice(world.root_qpos_adr, world.root_qpos_adr + 3)
        root_err[t] = float(np.linalg.norm(d.qpos[root] - qpos[t, root]))
        height[t] = d.qpos[z0]
        if fall is None and d.qpos[z0] < config.fall_height_ratio * qpos[t, z0]:
            fall = t
        if t == T - 1:
            break
        if mocap is not None:
            d.mocap_pos[:] = mocap[0][t]
            d.mocap_quat[:] = mocap[1][t]
        target_vel = half[t, J.dof_adr]
        for s in range(steps_per_frame):
            alpha = s / steps_per_frame
            target = (1.0 - alpha) * qpos[t, J.qpos_adr] + alpha * qpos[t + 1, J.qpos_adr]
            tau = config.tracking_kp * (target - d.qpos[J.qpos_adr]) + config.tracking_kd * (
                target_vel - d.qvel[J.dof_adr]
            )
            d.qfrc_applied[:] = 0.0
            d.qfrc_applied[J.dof_adr] = np.clip(tau, -limit, limit)
            mujoco.mj_step(m, d)
    failures = []
    if fall is not None:
        drop = float(np.max(qpos[fall:, z0] - height[fall:]))
        failures.append(Failure("tracking_fall", fall, T - 1, world.body_name(world.root_body), None, drop))
    time_up = (fall if fall is not None else T - 1) / fps
    return TrackingResult(joint_err, root_err, height, fall is not None, fall, time_up, failures)
