"""Dynamic feasibility: the "hand of god" a kinematic motion needs, and joint torques.

Per frame (MuJoCo's inverse dynamics, ``mj_inverse``; MuJoCo documentation, Computation):

1. ``mj_inverse`` with every constraint disabled (contacts included: MuJoCo's soft contact
   model would turn the kinematic data's penetrations into huge forces) on ``qpos`` and the
   finite-difference ``qvel``/``qacc`` gives the generalized force the motion needs,
   ``qfrc_inverse`` (root: world force + body-frame torque about the root; joints: torques).
2. The support contacts found by the kinematic replay (robot geoms within
   ``support_height_m`` of the floor or an obstacle) may push along their normal with a
   friction pyramid (4 edges, inscribed in the Coulomb cone). Their forces ``f >= 0`` are
   chosen by non-negative least squares to cancel the root's share of ``qfrc_inverse``,
   weighted so that a residual at the force threshold costs as much as one at the moment
   threshold, with a small ridge so that loads spread evenly.
3. What is left at the root is the non-physical wrench. It is reported as a force ratio
   ``|F| / (m g)`` and a moment about the centre of mass divided by ``m g`` (metres: how far
   the centre of pressure would have to move outside the support). Joint torques are
   ``qfrc_inverse - J^T f`` at the joints, compared with the model's torque limits.
4. Severity. A frame above a per-frame threshold is a *warning*: a kinematic motion from
   human data (20 fps, impacts smeared over neighbouring frames, a human's centre of mass
   that a 33 kg robot does not share) needs brief residual wrenches and torque peaks that
   a tracking controller absorbs. Averaged over ``sustained_window_s`` (the residual as
   an impulse over the supported frames, the torque ratio as a mean) the same quantities
   are *errors* above their sustained thresholds: a hand of god held for half a second
   (leaning past the toes, pushing off nothing) or a torque the motors cannot hold.

Unsupported frames thus need the whole wrench (about ``m g`` when hovering), except in a
ballistic flight where gravity alone explains the motion.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import mujoco
import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.optimize import nnls

from sim.config import CheckConfig
from sim.failures import Failure, from_mask
from sim.support import SupportContacts
from sim.world import CheckWorld

RIDGE = 1e-3
"""Ridge weight on contact forces (in units of m g) relative to the normalised residual."""
TORQUE_WEIGHT = 0.1
"""Weight of the joint torques (relative to their limits) in the force distribution: among
the contact forces that cancel the root wrench equally well, the check picks those that load
the joints least, as a controller would (a torque at its limit costs like 10 % of the
residual-force threshold)."""


@dataclass
class DynamicsResult:
    """Per-frame results of the inverse-dynamics check (T frames, J joints).

    Attributes:
        residual_force: (T, 3) non-physical force at the root (world, N).
        residual_moment: (T, 3) non-physical moment about the centre of mass (world, N m).
        residual_force_ratio: (T,) |residual force| / (m g).
        residual_moment_m: (T,) |residual moment| / (m g), metres.
        support_force: (T, 3) total force the support contacts carry (world, N).
        joint_torque: (T, J) actuator torques the motion needs (N m).
        torque_limit: (J,) limits (NaN: none); torque_ratio: (T, J) |torque| / limit.
        sustained_force_ratio: (T,) |residual force averaged over the window| / (m g), the
            unsupported frames counting zero (floating is the kinematic check's).
        sustained_moment_m: (T,) the same for the residual moment / (m g).
        sustained_torque_ratio: (T, J) |torque| / limit averaged over the window.
        failures: residual_force, residual_moment and torque_limit failures (warnings per
            frame, errors when sustained).
    """

    residual_force: np.ndarray
    residual_moment: np.ndarray
    residual_force_ratio: np.ndarray
    residual_moment_m: np.ndarray
    support_force: np.ndarray
    joint_torque: np.ndarray
    torque_limit: np.ndarray
    torque_ratio: np.ndarray
    sustained_force_ratio: np.ndarray
    sustained_moment_m: np.ndarray
    sustained_torque_ratio: np.ndarray
    failures: list[Failure] = field(default_factory=list)


def inverse_model(world: CheckWorld) -> mujoco.MjModel:
    """Copy of the model for rigid-body inverse dynamics: every constraint disabled."""
    m = copy.deepcopy(world.model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT) | int(
        mujoco.mjtDisableBit.mjDSBL_CONTACT
    )
    m.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_INVDISCRETE)
    return m


def _pyramid(normal: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Friction-pyramid edges, (K, 4, 3): n +- mu t1, n +- mu t2 (unit normal n)."""
    n = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    m = mu[:, None]
    return np.stack([n + m * t1, n - m * t1, n + m * t2, n - m * t2], axis=1)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def window_mean(values: np.ndarray, frames: int) -> np.ndarray:
    """Centred moving average over ``frames`` (odd), axis 0; nothing is assumed beyond the ends
    (zeros: a clip is not extrapolated)."""
    if frames <= 1 or len(values) < 2:
        return np.asarray(values, dtype=np.float64).copy()
    return uniform_filter1d(np.asarray(values, dtype=np.float64), size=frames, axis=0, mode="constant")


def dynamics_check(
    world: CheckWorld,
    qpos: np.ndarray,
    qvel: np.ndarray,
    qacc: np.ndarray,
    support: SupportContacts,
    config: CheckConfig,
    fps: float = 50.0,
    supported: np.ndarray | None = None,
) -> DynamicsResult:
    """Inverse dynamics of a trajectory against what its support can supply.

    Args:
        world: the robot + scene.
        qpos, qvel, qacc: (T, nq), (T, nv), (T, nv) from :mod:`sim.trajectory`.
        support: load-carrying contacts per frame (from :func:`sim.kinematic.kinematic_check`).
        config: thresholds (``max_residual_force_ratio``, ``max_residual_moment_m``,
            ``max_torque_ratio`` and their sustained counterparts).
        fps: frame rate (for the sustained window).
        supported: (T,) frames with a support (default: every frame); the sustained residual
            counts only those.
    """
    m = world.derived(("inverse",), lambda: inverse_model(world))
    d = mujoco.MjData(m)
    T = qpos.shape[0]
    mg = world.mass * float(np.linalg.norm(m.opt.gravity))
    if mg <= 0:
        mg = world.mass * 9.81
    root, dof0 = world.root_body, world.root_dof_adr
    root_dofs = np.arange(dof0, dof0 + 6)
    J = world.joints
    w_force = 1.0 / (mg * max(config.max_residual_force_ratio, 1e-6))
    w_moment = 1.0 / (mg * max(config.max_residual_moment_m, 1e-6))
    limited = np.isfinite(J.torque_limit) & (J.torque_limit > 0)
    tau_dofs = J.dof_adr[limited]
    w_tau = TORQUE_WEIGHT / J.torque_limit[limited]
    weights = np.array([w_force] * 3 + [w_moment] * 3)

    res_force = np.zeros((T, 3))
    res_moment = np.zeros((T, 3))
    sup_force = np.zeros((T, 3))
    torque = np.zeros((T, len(J.names)))
    order = np.argsort(support.frame, kind="stable")
    bounds = np.searchsorted(support.frame[order], np.arange(T + 1))
    jacp = np.zeros((3, m.nv))
    all_edges = _pyramid(support.normal, support.friction) if support.frame.size else np.zeros((0, 4, 3))
    sqrt_ridge = np.sqrt(RIDGE)
    for t in range(T):
        d.qpos[:] = qpos[t]
        d.qvel[:] = qvel[t]
        d.qacc[:] = qacc[t]
        mujoco.mj_inverse(m, d)
        need = d.qfrc_inverse.copy()
        rot = d.xmat[root].reshape(3, 3)
        com = d.subtree_com[root].copy()
        lever = d.xpos[root] - com
        # root generalized force -> [force (world); moment about the CoM (world)]
        to_com = np.zeros((6, 6))
        to_com[:3, :3] = np.eye(3)
        to_com[3:, :3] = _skew(lever)
        to_com[3:, 3:] = rot
        idx = order[bounds[t] : bounds[t + 1]]
        generalized = np.zeros(m.nv)
        if idx.size:
            edges = all_edges[idx]  # (K, 4, 3)
            cols = np.empty((m.nv, idx.size * 4))
            for i, c in enumerate(idx):
                mujoco.mj_jac(m, d, jacp, None, support.pos[c], int(support.body[c]))
                cols[:, 4 * i : 4 * i + 4] = jacp.T @ edges[i].T
            a = weights[:, None] * (to_com @ cols[root_dofs]) * mg
            b = weights * (to_com @ need[root_dofs])
            a_tau = w_tau[:, None] * cols[tau_dofs] * mg
            b_tau = w_tau * need[tau_dofs]
            lhs = np.vstack([a, a_tau, sqrt_ridge * np.eye(a.shape[1])])
            rhs = np.concatenate([b, b_tau, np.zeros(a.shape[1])])
            lam, _ = nnls(lhs, rhs, maxiter=50 * a.shape[1])
            forces = lam * mg
            generalized = cols @ forces
            sup_force[t] = np.einsum("kej,ke->j", edges, forces.reshape(-1, 4))
        residual = to_com @ (need[root_dofs] - generalized[root_dofs])
        res_force[t] = residual[:3]
        res_moment[t] = residual[3:]
        torque[t] = need[J.dof_adr] - generalized[J.dof_adr]

    force_ratio = np.linalg.norm(res_force, axis=1) / mg
    moment_m = np.linalg.norm(res_moment, axis=1) / mg
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.abs(torque) / J.torque_limit
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    # Sustained: impulses over the window (supported frames only) and mean torque ratios.
    on = np.ones(T, dtype=bool) if supported is None else np.asarray(supported, dtype=bool)
    width = max(1, int(round(config.sustained_window_s * fps)) // 2 * 2 + 1)
    sus_force = np.linalg.norm(window_mean(res_force * on[:, None], width), axis=1) / mg
    sus_moment = np.linalg.norm(window_mean(res_moment * on[:, None], width), axis=1) / mg
    sus_torque = window_mean(ratio, width) if ratio.size else ratio
    per_frame = "error" if config.strict_dynamics else "warning"
    failures = from_mask("residual_force", sus_force > config.max_sustained_residual_force_ratio, sus_force)
    failures += from_mask("residual_moment", sus_moment > config.max_sustained_residual_moment_m, sus_moment)
    failures += from_mask(
        "residual_force", force_ratio > config.max_residual_force_ratio, force_ratio, severity=per_frame
    )
    failures += from_mask(
        "residual_moment", moment_m > config.max_residual_moment_m, moment_m, severity=per_frame
    )
    for j, name in enumerate(J.names):
        failures += from_mask(
            "torque_limit",
            sus_torque[:, j] > config.max_sustained_torque_ratio,
            sus_torque[:, j],
            robot_body=J.bodies[j],
            joint=name,
        )
        failures += from_mask(
            "torque_limit",
            ratio[:, j] > config.max_torque_ratio,
            ratio[:, j],
            robot_body=J.bodies[j],
            joint=name,
            severity=per_frame,
        )
    return DynamicsResult(
        res_force,
        res_moment,
        force_ratio,
        moment_m,
        sup_force,
        torque,
        J.torque_limit.copy(),
        ratio,
        sus_force,
        sus_moment,
        sus_torque,
        failures,
    )
