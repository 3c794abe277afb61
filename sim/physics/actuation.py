"""The robot's actuators as the controller sees them: position targets with PD gains.

The controller always plans **position targets** (one per actuator, in the actuator's length
units: gear x joint angle). How a target becomes the control input depends on the MJCF:

* a position servo (``<position>``: fixed gain kp, affine bias ``-kp q - kv qdot``, e.g. the
  Menagerie G1) takes the target as its ``ctrl`` directly: MuJoCo applies the PD itself, with
  the MJCF's gains, clipped to its force range and the joint's ``actuatorfrcrange``;
* a motor (``<motor>``: ``ctrl`` is a force, e.g. the Menagerie H1) gets, at every step, the
  force ``kp (target - gear q) - kv gear qdot`` clipped to its ``ctrlrange``, with the gains of
  ``PhysicsConfig``'s caller (default those of the PD replay, ``CheckConfig.tracking_kp/kd``).
  The planning model replaces such motors by position servos with the same gains and force
  range, which is what the executed PD does.

Only joint transmissions are supported (every humanoid of the robot library uses them).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from controlmm.errors import ControlMMError

_JOINT = int(mujoco.mjtTrn.mjTRN_JOINT)
_FIXED = int(mujoco.mjtGain.mjGAIN_FIXED)
_AFFINE = int(mujoco.mjtBias.mjBIAS_AFFINE)
_NONE_BIAS = int(mujoco.mjtBias.mjBIAS_NONE)
_NONE_DYN = int(mujoco.mjtDyn.mjDYN_NONE)


@dataclass(frozen=True)
class Actuation:
    """Per-actuator arrays, shape (nu,) unless stated.

    Attributes:
        names: actuator names.
        joint: joint id of each actuator; qpos_adr / dof_adr: its qpos and qvel addresses.
        gear: transmission gear (actuator length = gear x joint angle).
        servo: True for position servos (ctrl = target), False for motors (ctrl = force).
        kp, kv: PD gains in actuator units (force per length, force per length rate).
        target_low, target_high: allowed targets (the servo's ctrlrange, else the joint range).
        force_low, force_high: force range of motors (their ctrlrange x gain); +-inf for servos.
        motor_gain: a motor's force per unit of ctrl (1 for servos).
    """

    names: tuple[str, ...]
    joint: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    gear: np.ndarray
    servo: np.ndarray
    kp: np.ndarray
    kv: np.ndarray
    target_low: np.ndarray
    target_high: np.ndarray
    force_low: np.ndarray
    force_high: np.ndarray
    motor_gain: np.ndarray

    @property
    def nu(self) -> int:
        return len(self.names)

    @property
    def all_servos(self) -> bool:
        return bool(self.servo.all())

    def nominal_targets(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Targets that give joint torques ``tau`` at joint angles ``q`` and velocities ``qd``.

        All arrays (..., nu) in actuator order (``q``/``qd`` are the actuated joints' values).
        Clipped to the allowed targets.
        """
        target = self.gear * q + (tau / self.gear + self.kv * self.gear * qd) / self.kp
        return np.clip(target, self.target_low, self.target_high)

    def controls(self, target: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """The ``ctrl`` vector (nu,) that realises ``target`` in the current state."""
        target = np.clip(target, self.target_low, self.target_high)
        if self.all_servos:
            return target
        force = (
            self.kp * (target - self.gear * qpos[self.qpos_adr]) - self.kv * self.gear * qvel[self.dof_adr]
        )
        force = np.clip(force, self.force_low, self.force_high)
        return np.where(self.servo, target, force / self.motor_gain)


def actuation(model: mujoco.MjModel, motor_kp: float, motor_kv: float) -> Actuation:
    """Read the actuators of ``model`` (one line of error for an unsupported one)."""
    if model.nu == 0:
        raise ControlMMError("the robot has no actuators; the physics check drives it through its actuators")
    nu = model.nu
    joint = np.zeros(nu, dtype=np.int64)
    gear = np.ones(nu)
    servo = np.zeros(nu, dtype=bool)
    kp, kv = np.zeros(nu), np.zeros(nu)
    t_lo, t_hi = np.full(nu, -np.inf), np.full(nu, np.inf)
    f_lo, f_hi = np.full(nu, -np.inf), np.full(nu, np.inf)
    motor_gain = np.ones(nu)
    names = []
    for a in range(nu):
        name = model.actuator(a).name or f"actuator{a}"
        names.append(name)
        if model.actuator_trntype[a] != _JOINT:
            raise ControlMMError(
                f"actuator '{name}' does not drive a joint; only joint actuators are supported"
            )
        j = int(model.actuator_trnid[a, 0])
        g = float(model.actuator_gear[a, 0])
        if g == 0:
            raise ControlMMError(f"actuator '{name}' has gear 0")
        joint[a], gear[a] = j, g
        gain, bias = model.actuator_gainprm[a], model.actuator_biasprm[a]
        fixed = model.actuator_gaintype[a] == _FIXED and model.actuator_dyntype[a] == _NONE_DYN
        lo, hi = sorted((g * model.jnt_range[j, 0], g * model.jnt_range[j, 1]))
        joint_limited = bool(model.jnt_limited[j])
        if (
            fixed
            and model.actuator_biastype[a] == _AFFINE
            and gain[0] > 0
            and bias[0] == 0
            and np.isclose(bias[1], -gain[0])
        ):
            servo[a], kp[a], kv[a] = True, float(gain[0]), float(-bias[2])
            if model.actuator_ctrllimited[a]:
                t_lo[a], t_hi[a] = model.actuator_ctrlrange[a]
            elif joint_limited:
                t_lo[a], t_hi[a] = lo, hi
        elif fixed and model.actuator_biastype[a] == _NONE_BIAS and gain[0] != 0:
            kp[a], kv[a] = motor_kp / g**2, motor_kv / g**2
            motor_gain[a] = float(gain[0])
            if joint_limited:
                t_lo[a], t_hi[a] = lo, hi
            if model.actuator_ctrllimited[a]:
                f_lo[a], f_hi[a] = sorted(model.actuator_ctrlrange[a] * gain[0])
        else:
            raise ControlMMError(
                f"actuator '{name}' is neither a position servo nor a motor; the physics check supports those"
            )
    return Actuation(
        names=tuple(names),
        joint=joint,
        qpos_adr=np.array([model.jnt_qposadr[j] for j in joint], dtype=np.int64),
        dof_adr=np.array([model.jnt_dofadr[j] for j in joint], dtype=np.int64),
        gear=gear,
        servo=servo,
        kp=kp,
        kv=kv,
        target_low=t_lo,
        target_high=t_hi,
        force_low=f_lo,
        force_high=f_hi,
        motor_gain=motor_gain,
    )


def servo_planning(model: mujoco.MjModel, act: Actuation) -> None:
    """Turn the motors of ``model`` (read as ``act``) into the position servos the PD emulates
    (in place: the planning copy's actuator fields)."""
    for a in range(model.nu):
        if act.servo[a]:
            continue
        model.actuator_gaintype[a] = _FIXED
        model.actuator_biastype[a] = _AFFINE
        model.actuator_gainprm[a] = 0.0
        model.actuator_gainprm[a, 0] = act.kp[a]
        model.actuator_biasprm[a] = 0.0
        model.actuator_biasprm[a, 1], model.actuator_biasprm[a, 2] = -act.kp[a], -act.kv[a]
        if np.isfinite(act.force_low[a]):
            model.actuator_forcelimited[a] = 1
            model.actuator_forcerange[a] = [act.force_low[a], act.force_high[a]]
        if np.isfinite(act.target_low[a]):
            model.actuator_ctrllimited[a] = 1
            model.actuator_ctrlrange[a] = [act.target_low[a], act.target_high[a]]
        else:
            model.actuator_ctrllimited[a] = 0
