"""What a robot's motors can do at each joint, as its MJCF states it.

* :func:`joint_torque_limits`: the largest torque (N m; N for a slide) the model lets act on
  each joint: its ``actuatorfrcrange``, or the force range of the motors driving it (times
  their gear), or for a plain motor (no bias, fixed gain) its control range times gain and
  gear; the smallest of those that apply, NaN where the model states none.
* :func:`joint_speed_limits`: the fastest each joint may turn (rad/s): published figures for
  the G1 and H1, 3 pi (GMR's IK velocity limit) for the others.
* :func:`damping_share`: joint damping over that limit (s/rad): the share of the motor a joint
  moving at 1 rad/s spends on its own damping (MuJoCo's passive force ``-damping * qvel``,
  which the actuators must overcome in simulation). A joint with damping 200 N m s/rad and a
  120 N m motor (the Apollo's torso yaw) can turn no faster than 0.6 rad/s
  (:func:`damped_speed_limits`: the speed rungs keep joints under it).
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

PUBLISHED_VELOCITY_LIMITS: dict[str, float] = {
    # Unitree G1 (29 DoF), rad/s: whole_body_tracking robots/g1.py `velocity_limit_sim`
    # (= Unitree's G1 URDF `velocity` attributes); Menagerie's MJCF has none.
    **{
        f"{s}_{j}": v
        for s in ("left", "right")
        for j, v in (
            ("hip_pitch_joint", 32.0),
            ("hip_roll_joint", 20.0),
            ("hip_yaw_joint", 32.0),
            ("knee_joint", 20.0),
            ("ankle_pitch_joint", 37.0),
            ("ankle_roll_joint", 37.0),
            ("shoulder_pitch_joint", 37.0),
            ("shoulder_roll_joint", 37.0),
            ("shoulder_yaw_joint", 37.0),
            ("elbow_joint", 37.0),
            ("wrist_roll_joint", 37.0),
            ("wrist_pitch_joint", 22.0),
            ("wrist_yaw_joint", 22.0),
        )
    },
    "waist_yaw_joint": 32.0,
    "waist_roll_joint": 37.0,
    "waist_pitch_joint": 37.0,
    # Unitree H1 (19 DoF), rad/s: unitree_ros robots/h1_description/urdf/h1.urdf `velocity`
    # attributes; Menagerie names the joints without the `_joint` suffix.
    **{
        f"{s}_{j}": v
        for s in ("left", "right")
        for j, v in (
            ("hip_yaw", 23.0),
            ("hip_roll", 23.0),
            ("hip_pitch", 23.0),
            ("knee", 14.0),
            ("ankle", 9.0),
            ("shoulder_pitch", 9.0),
            ("shoulder_roll", 9.0),
            ("shoulder_yaw", 20.0),
            ("elbow", 20.0),
        )
    },
    "torso": 23.0,
}
"""Published joint velocity limits (rad/s) by MJCF joint name (G1 and H1 of Menagerie)."""

DEFAULT_VELOCITY_LIMIT = 3.0 * np.pi
"""rad/s for joints without a published limit: GMR's IK velocity limit (3 pi)."""


def joint_speed_limits(names: Sequence[str]) -> np.ndarray:
    """(J,) the speed limit (rad/s; m/s for a slide) of each joint named: its published one
    (``PUBLISHED_VELOCITY_LIMITS``, a namespace prefix such as ``robot/`` ignored), else
    ``DEFAULT_VELOCITY_LIMIT``. ``controlmm validate`` checks the same ones (sim.config)."""
    return np.array(
        [PUBLISHED_VELOCITY_LIMITS.get(n.rsplit("/", 1)[-1], DEFAULT_VELOCITY_LIMIT) for n in names]
    )


def joint_torque_limits(model: mujoco.MjModel, joints: Sequence[int] | np.ndarray) -> np.ndarray:
    """(J,) the torque limit of each of ``joints`` (MuJoCo joint ids of hinges or slides);
    NaN where the model states none (see the module docstring)."""
    rows = {int(j): i for i, j in enumerate(joints)}
    torque = np.full(len(rows), np.nan)
    for j, row in rows.items():
        if model.jnt_actfrclimited[j]:
            torque[row] = float(np.max(np.abs(model.jnt_actfrcrange[j])))
    for a in range(model.nu):
        if model.actuator_trntype[a] != int(mujoco.mjtTrn.mjTRN_JOINT):
            continue
        i = rows.get(int(model.actuator_trnid[a, 0]))
        if i is None:
            continue
        gear = abs(float(model.actuator_gear[a, 0]))
        if model.actuator_forcelimited[a]:
            limit = float(np.max(np.abs(model.actuator_forcerange[a]))) * gear
        elif (
            model.actuator_biastype[a] == int(mujoco.mjtBias.mjBIAS_NONE)
            and model.actuator_gaintype[a] == int(mujoco.mjtGain.mjGAIN_FIXED)
            and model.actuator_dyntype[a] == int(mujoco.mjtDyn.mjDYN_NONE)
            and model.actuator_ctrllimited[a]
        ):
            limit = (
                float(np.max(np.abs(model.actuator_ctrlrange[a])))
                * abs(float(model.actuator_gainprm[a, 0]))
                * gear
            )
        else:
            continue
        torque[i] = limit if np.isnan(torque[i]) else min(torque[i], limit)
    return torque


def damping_share(model: mujoco.MjModel, joints: Sequence[int] | np.ndarray) -> np.ndarray:
    """(J,) each joint's damping over its torque limit (s/rad; 0 without damping or a limit)."""
    ids = np.asarray(joints, dtype=np.int64)
    limit = joint_torque_limits(model, ids)
    damping = model.dof_damping[model.jnt_dofadr[ids]]
    ok = np.isfinite(limit) & (limit > 0)
    return np.where(ok, damping / np.where(ok, limit, 1.0), 0.0)


def damped_speed_limits(share: np.ndarray) -> np.ndarray:
    """(J,) the speed (rad/s) at which each joint's damping alone takes its whole motor, from
    ``share`` (J,) (:func:`damping_share`: damping over torque limit); inf without either."""
    share = np.asarray(share, dtype=np.float64)
    return np.where(share > 0, 1.0 / np.where(share > 0, share, 1.0), np.inf)
