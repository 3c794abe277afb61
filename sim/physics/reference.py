"""The reference the controller tracks, resampled from the trajectory's frames to simulation steps.

From the kinematic trajectory (``qpos`` at ``fps``) and the inverse-dynamics check's joint
torques (``sim.dynamics``: the torques the motion needs with its support forces distributed
over the feet), per simulation step:

* the nominal actuator targets: PD targets plus the feed-forward torque turned into a target
  offset (:meth:`sim.physics.actuation.Actuation.nominal_targets`);
* what the cost compares with: root position and orientation, actuated joint angles, the
  robot's centre of mass and its velocity, the feet positions.

Per frame, for the sampler: the *foot basis*, which maps a small twist of each foot relative
to the root (3 translations, 3 rotations, world axes) to the leg joints' target offsets by
damped least squares on the foot's Jacobian, plus one column per other actuator. Sampling
in that basis moves feet coherently (a step placed 3 cm further, a sole tilted 5 degrees)
instead of jittering joints one by one.

Linear interpolation between frames; the root quaternion is normalised after interpolation.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import uniform_filter1d

from sim.physics.actuation import Actuation
from sim.physics.config import PhysicsConfig
from sim.world import CheckWorld

FEEDFORWARD_WINDOW_S = 0.1
"""The feed-forward torques are averaged over this window: they come from second differences of
the trajectory, whose single-frame spikes are the smeared image of impacts."""
JACOBIAN_DAMPING = 1e-3
"""Damping (m^2) of the foot basis' least squares: bounded offsets near a straight knee."""


@dataclass
class Reference:
    """Reference arrays. S = simulation steps, T = frames, F = feet, E = end effectors.

    Attributes:
        dt: simulation timestep (s); fps: trajectory rate; steps: S (the last state is S).
        frame_qpos: (T, nq) the trajectory; frame_qvel: (T, nv) its finite-difference velocities.
        nominal: (S+1, nu) nominal actuator targets.
        root_pos: (S+1, 3); root_quat: (S+1, 4, wxyz); joints: (S+1, nu) actuated joint angles.
        com: (S+1, 3) centre of mass; com_vel: (S+1, 3); feet: (S+1, F, 3) foot body positions.
        basis: (T, nu, Z) foot basis per frame; sigma: (Z,) noise of each basis coordinate.
        effectors: (E,) ids of the end-effector bodies (feet, hands: the leaves of the robot's tree).
        frame_effectors: (T, E, 3) their positions relative to the root, in the root's frame.
        frame_up: (T, 3) the root's up axis (world).
        flight: (S+1,) steps within ``flight_margin_s`` of a flight phase of the reference.
    """

    dt: float
    fps: float
    steps: int
    frame_qpos: np.ndarray
    frame_qvel: np.ndarray
    nominal: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    joints: np.ndarray
    com: np.ndarray
    com_vel: np.ndarray
    feet: np.ndarray
    basis: np.ndarray
    sigma: np.ndarray
    effectors: np.ndarray
    frame_effectors: np.ndarray
    frame_up: np.ndarray
    flight: np.ndarray

    def frame_of_step(self, step: np.ndarray | int) -> np.ndarray:
        """Fractional frame index of simulation step(s)."""
        return np.minimum(np.asarray(step) * self.dt * self.fps, self.frame_qpos.shape[0] - 1)

    def basis_at(self, steps: np.ndarray) -> np.ndarray:
        """(len(steps), nu, Z) foot basis interpolated at simulation steps."""
        x = self.frame_of_step(steps)
        i0 = np.floor(x).astype(np.int64)
        i1 = np.minimum(i0 + 1, self.basis.shape[0] - 1)
        a = (x - i0)[:, None, None]
        return (1.0 - a) * self.basis[i0] + a * self.basis[i1]


def resample(values: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of per-frame ``values`` (T, ...) at ``times`` (s); clamped at the ends."""
    x = np.clip(times * fps, 0.0, values.shape[0] - 1)
    i0 = np.floor(x).astype(np.int64)
    i1 = np.minimum(i0 + 1, values.shape[0] - 1)
    a = (x - i0).reshape((-1,) + (1,) * (values.ndim - 1))
    return (1.0 - a) * values[i0] + a * values[i1]


def leaf_bodies(world: CheckWorld) -> np.ndarray:
    """Robot bodies without child bodies (feet, hands, head: the end effectors)."""
    m = world.model
    robot = set(world.robot_bodies.tolist())
    parents = {int(m.body_parentid[b]) for b in robot if b != world.root_body}
    return np.array(sorted(b for b in robot if b not in parents), dtype=np.int64)


def _legs(world: CheckWorld, act: Actuation, data: mujoco.MjData) -> list[np.ndarray]:
    """Per foot: the actuators moving it relative to the root (non-zero Jacobian columns)."""
    m = world.model
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    root = world.root_dof_adr
    out = []
    for foot in world.feet:
        mujoco.mj_jacBody(m, data, jacp, jacr, foot.body)
        moving = np.abs(np.vstack([jacp, jacr])).max(axis=0) > 1e-9
        moving[root : root + 6] = False
        out.append(np.flatnonzero(moving[act.dof_adr]))
    return out


def build_reference(
    world: CheckWorld,
    act: Actuation,
    qpos: np.ndarray,
    qvel: np.ndarray,
    fps: float,
    joint_torque: np.ndarray,
    timestep: float,
    config: PhysicsConfig,
    flight: np.ndarray | None = None,
) -> Reference:
    """Resample a validated trajectory to simulation steps (see the module docstring).

    Args:
        world: robot + scene; act: its actuators.
        qpos, qvel: (T, nq), (T, nv) the trajectory and its finite-difference velocities.
        fps: trajectory rate; timestep: simulation step (s).
        joint_torque: (T, J) torques the motion needs, in ``world.joints`` order (``sim.dynamics``).
        config: noise scales of the basis, the flight margin.
        flight: (T,) frames in a flight phase (``KinematicResult.flight``), or None.
    """
    m = world.model
    T = qpos.shape[0]
    steps = int(round((T - 1) / fps / timestep))
    times = np.arange(steps + 1) * timestep
    joint_of = {int(j): i for i, j in enumerate(world.joints.dof_adr)}
    tau = joint_torque[:, [joint_of[int(d)] for d in act.dof_adr]]
    window = max(1, int(round(FEEDFORWARD_WINDOW_S * fps)))
    tau = uniform_filter1d(tau, window, axis=0, mode="nearest") if T > 1 else tau
    q_act, qd_act = qpos[:, act.qpos_adr], qvel[:, act.dof_adr]
    nominal = act.nominal_targets(
        resample(q_act, fps, times), resample(qd_act, fps, times), resample(tau, fps, times)
    )

    data = mujoco.MjData(m)
    effectors = leaf_bodies(world)
    feet = np.array([f.body for f in world.feet], dtype=np.int64)
    com = np.zeros((T, 3))
    foot_pos = np.zeros((T, feet.size, 3))
    eff = np.zeros((T, effectors.size, 3))
    up = np.zeros((T, 3))
    root = world.root_body
    nz_legs = 6 * len(world.feet)
    data.qpos[:] = qpos[0]
    mujoco.mj_kinematics(m, data)
    mujoco.mj_comPos(m, data)
    legs = _legs(world, act, data)
    in_leg = np.zeros(act.nu, dtype=bool)
    for leg in legs:
        in_leg[leg] = True
    rest = np.flatnonzero(~in_leg)
    basis = np.zeros((T, act.nu, nz_legs + rest.size))
    basis[:, rest, nz_legs + np.arange(rest.size)] = act.gear[rest]
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(m, data)
        mujoco.mj_comPos(m, data)
        com[t] = data.subtree_com[root]
        foot_pos[t] = data.xpos[feet]
        rot = data.xmat[root].reshape(3, 3)
        eff[t] = (data.xpos[effectors] - data.xpos[root]) @ rot
        up[t] = rot[:, 2]
        for i, foot in enumerate(world.feet):
            mujoco.mj_jacBody(m, data, jacp, jacr, foot.body)
            jac = np.vstack([jacp, jacr])[:, act.dof_adr[legs[i]]]
            pinv = jac.T @ np.linalg.inv(jac @ jac.T + JACOBIAN_DAMPING * np.eye(6))
            basis[t, legs[i], 6 * i : 6 * i + 6] = pinv * act.gear[legs[i], None]
    sigma = np.zeros(basis.shape[2])
    for i in range(len(world.feet)):
        sigma[6 * i : 6 * i + 3] = config.sigma_foot_m
        sigma[6 * i + 3 : 6 * i + 6] = config.sigma_foot_rad
    for k, a in enumerate(rest):
        wrist = "wrist" in act.names[a].lower() or "wrist" in (m.joint(int(act.joint[a])).name or "").lower()
        sigma[nz_legs + k] = 0.0 if wrist and not config.wrist_noise else config.sigma_joint_rad
    com_vel = np.asarray(np.gradient(com, 1.0 / fps, axis=0)) if T > 1 else np.zeros_like(com)
    near_flight = np.zeros(steps + 1, dtype=bool)
    if flight is not None and np.any(flight):
        times_f = np.flatnonzero(flight) / fps
        margin = config.flight_margin_s
        near = np.abs(times[:, None] - times_f[None, :]).min(axis=1) <= margin
        near_flight[:] = near
    root_adr = world.root_qpos_adr
    root_quat = resample(qpos[:, root_adr + 3 : root_adr + 7], fps, times)
    root_quat /= np.linalg.norm(root_quat, axis=1, keepdims=True)
    return Reference(
        dt=timestep,
        fps=fps,
        steps=steps,
        frame_qpos=qpos,
        frame_qvel=qvel,
        nominal=nominal,
        root_pos=resample(qpos[:, root_adr : root_adr + 3], fps, times),
        root_quat=root_quat,
        joints=resample(q_act, fps, times),
        com=resample(com, fps, times),
        com_vel=resample(com_vel, fps, times),
        feet=resample(foot_pos, fps, times),
        basis=basis,
        sigma=sigma,
        effectors=effectors,
        frame_effectors=eff,
        frame_up=up,
        flight=near_flight,
    )
