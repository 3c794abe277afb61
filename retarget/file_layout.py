"""A trajectory in the robot file's own qpos layout, where the retargeter edited the file.

:func:`retarget.robot_files.read_robot_mjcf` may change a humanoid MJCF's joints before it
retargets (:mod:`retarget.spec_edits`): a floating base written as three slides and three
hinges or a ball becomes one free joint, the passive rods of closed chains and joints on
bodies beside the robot are dropped. Its trajectories then have another qpos than the file:
a user (or a checker) who loads the file as given and sets ``data.qpos`` from them would not
fit. :class:`FileLayout` writes them in the file's layout: the joints both have copied by
name, the rest solved per frame from the file's own kinematics (Levenberg-Marquardt on their
degrees of freedom, MuJoCo's Jacobians): the base joints put the root body where the free
joint does, the rods and the cranks that drive them close their loops (the ``<connect>`` and
``<weld>`` constraints' own residuals) as far as the linkage reaches. Joints on bodies beside
the robot stay at ``qpos0``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from retarget.spec_edits import joint_addresses

ITERATIONS = 30
"""Levenberg-Marquardt iterations per frame at most (a frame starts from the one before)."""
TOLERANCE = 1e-16
"""Stop once the squared residual (m^2 and rad^2) is below this."""
LOOSE = 1e-6
"""A frame left with more squared residual than this did not close: it is solved again from
the rest pose, the better of the two kept."""
STALL = 1e-4
"""Stop once an accepted step lowers the squared residual by less than this fraction (a loop
its linkage cannot close)."""
MAX_STEP = 0.3
"""Largest change (rad or m) of one degree of freedom in one step."""


@dataclass(frozen=True)
class FileLayout:
    """How the retargeter's qpos (``nq`` of the edited model) maps onto the file's (``model``).

    Attributes:
        model: the robot file compiled as given (contacts off).
        src, dst: (K,) qpos addresses copied from the edited model's qpos to the file's.
        solve: (S,) the file's dof addresses solved for (base joints, rods).
        root: the file's body carrying the edited model's free joint; ``base``: whether the
            file moves it with other joints (their pose residual is solved for).
        limited: (L,) qpos addresses of the solved hinges and slides with a range; lower,
            upper: (L,) their ranges.
    """

    model: mujoco.MjModel
    src: np.ndarray
    dst: np.ndarray
    solve: np.ndarray
    root: int
    base: bool
    limited: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    def to_file(self, qpos: np.ndarray) -> np.ndarray:
        """``qpos`` (T, nq edited, free joint first) as (T, nq of the file)."""
        m = self.model
        d = mujoco.MjData(m)
        out = np.tile(m.qpos0, (len(qpos), 1))
        out[:, self.dst] = qpos[:, self.src]
        if not len(self.solve):
            return out
        q = m.qpos0.copy()
        for t in range(len(qpos)):
            q[self.dst] = qpos[t, self.src]
            q, cost = self._solve_frame(d, q, qpos[t, 0:3], qpos[t, 3:7])
            if cost > LOOSE:  # not closed from the frame before: from rest too, the better kept
                rest = out[t].copy()
                rest, rest_cost = self._solve_frame(d, rest, qpos[t, 0:3], qpos[t, 3:7])
                q = rest if rest_cost < cost else q
            out[t] = q
        return out

    def _residual(
        self, d: mujoco.MjData, q: np.ndarray, pos: np.ndarray, goal_rot: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The residuals (root pose, m and rad; equality constraints) at ``q`` and their
        Jacobian in the ``solve`` dofs."""
        m = self.model
        d.qpos[:] = q
        mujoco.mj_forward(m, d)
        rows_r, rows_j = [np.zeros(0)], [np.zeros((0, m.nv))]
        if self.base:
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            err, rel = np.zeros(3), np.zeros(4)
            mujoco.mju_mat2Quat(rel, (goal_rot.T @ d.xmat[self.root].reshape(3, 3)).ravel())
            mujoco.mju_quat2Vel(err, rel, 1.0)  # rotation vector in the goal's frame
            mujoco.mj_jacBody(m, d, jacp, jacr, self.root)
            rows_r += [d.xpos[self.root] - pos, goal_rot @ err]
            rows_j += [jacp, jacr]
        eq = d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        if eq.any():
            jac = _dense_efc(m, d) if mujoco.mj_isSparse(m) else d.efc_J.reshape(d.nefc, m.nv)
            rows_r.append(d.efc_pos[: d.nefc][eq])
            rows_j.append(jac[eq])
        return np.concatenate(rows_r), np.vstack(rows_j)[:, self.solve]

    def _solve_frame(
        self, d: mujoco.MjData, q: np.ndarray, pos: np.ndarray, quat: np.ndarray
    ) -> tuple[np.ndarray, float]:
        """The file's qpos ``q`` with its ``solve`` dofs moved (Levenberg-Marquardt, limits
        kept) so that the root body has the pose (pos, quat wxyz) and the equality
        constraints hold, and its squared residual."""
        m = self.model
        goal = np.zeros(9)
        mujoco.mju_quat2Mat(goal, quat)
        goal_rot = goal.reshape(3, 3)
        r, j = self._residual(d, q, pos, goal_rot)
        cost, mu = float(r @ r), 1e-6
        for _ in range(ITERATIONS):
            if cost < TOLERANCE:
                break
            step = np.linalg.solve(j.T @ j + mu * np.eye(j.shape[1]), -(j.T @ r))
            step *= min(1.0, MAX_STEP / max(float(np.abs(step).max()), 1e-12))
            dv = np.zeros(m.nv)
            dv[self.solve] = step
            trial = q.copy()
            mujoco.mj_integratePos(m, trial, dv, 1.0)
            trial[self.limited] = np.clip(trial[self.limited], self.lower, self.upper)
            r2, j2 = self._residual(d, trial, pos, goal_rot)
            new = float(r2 @ r2)
            if new < cost:
                stalled = cost - new < STALL * cost
                q, r, j, cost, mu = trial, r2, j2, new, max(mu / 10, 1e-9)
                if stalled:
                    break
            else:
                mu *= 10
        return q, cost


def _dense_efc(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    out = np.zeros((d.nefc, m.nv))
    mujoco.mju_sparse2dense(out, d.efc_J, d.efc_J_rownnz, d.efc_J_rowadr, d.efc_J_colind)
    return out


def _joints(m: mujoco.MjModel) -> dict[str, int]:
    return {m.joint(j).name: j for j in range(m.njnt) if m.joint(j).name}


def _loop_joints(m: mujoco.MjModel, dropped: set[int], main: set[int]) -> set[int]:
    """The joints of the cranks that drive the dropped bodies (rods) of closed loops: going up
    from each rod, every jointed body whose other jointed bodies below are all rods (a crank
    on the shin whose rod drives the ankle, a lever on the trunk whose rod drives the waist),
    up to the first body that carries more of the robot (the shin, the trunk) or that the
    mapping follows (``main``: a foot a rod hangs from): that main chain stays as retargeted,
    the cranks turn to close the loops."""
    jointed = {int(m.jnt_bodyid[j]) for j in range(m.njnt)}
    below: dict[int, set[int]] = {b: set() for b in range(m.nbody)}
    for b in range(m.nbody - 1, 0, -1):  # children have larger ids than their parents
        parent = int(m.body_parentid[b])
        below[parent] |= below[b] | ({b} & jointed)
    out: set[int] = set()
    for rod in dropped:
        b = rod
        while b != 0 and below[b] <= dropped and b not in main:
            out |= {j for j in range(m.njnt) if int(m.jnt_bodyid[j]) == b}
            b = int(m.body_parentid[b])
    return out


def _file_root(m: mujoco.MjModel, name: str) -> int:
    """The file's body named ``name``, or (a root body the edits had to name) the body of the
    world whose subtree holds the most joints."""
    if name in {m.body(b).name for b in range(m.nbody)}:
        return m.body(name).id
    children = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0]
    return max(children, key=lambda b: int(np.sum(m.body_rootid[m.jnt_bodyid] == b)))


def file_layout(path: str | Path, edited: mujoco.MjModel, main: Iterable[str] = ()) -> FileLayout | None:
    """The layout of the robot file ``path`` for trajectories of ``edited`` (the model the
    retargeter read from it); None where both have the same joints in the same order (every
    file the edits leave alone), or where the file as given does not compile. ``main``: the
    names of the bodies the mapping follows and their ancestors (never turned to close a loop)."""
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        written = [(j.name, int(j.type)) for j in spec.joints]
        if written == [(edited.joint(j).name, int(edited.jnt_type[j])) for j in range(edited.njnt)]:
            return None  # the same joints in the same order: the same qpos (no compile needed)
        m = spec.compile()
    except ValueError:
        return None
    ours, theirs = _joints(edited), _joints(m)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    free = next(j for j in range(edited.njnt) if edited.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE)
    root_name = edited.body(int(edited.jnt_bodyid[free])).name
    root = _file_root(m, root_name)
    src: list[int] = []
    dst: list[int] = []
    for name, j in ours.items():
        if name in theirs and m.jnt_type[theirs[name]] == edited.jnt_type[j]:
            src += list(joint_addresses(edited, j)[0])
            dst += list(joint_addresses(m, theirs[name])[0])
    copied = {theirs[n] for n in ours if n in theirs}
    base = not any(m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and j in copied for j in range(m.njnt))
    robot = {b for b in range(m.nbody) if m.body_rootid[b] == m.body_rootid[root]}
    moved = {j for j in range(m.njnt) if j not in copied and int(m.jnt_bodyid[j]) in robot}
    names = set(main)
    keep = {b for b in range(m.nbody) if m.body(b).name in names}
    moved |= _loop_joints(m, {int(m.jnt_bodyid[j]) for j in moved} - {root}, keep)
    solve = [dof for j in sorted(moved) for dof in joint_addresses(m, j)[1]]
    limited = [j for j in sorted(moved) if m.jnt_limited[j] and m.jnt_type[j] in (2, 3)]
    return FileLayout(
        m,
        np.array(src, dtype=int),
        np.array(dst, dtype=int),
        np.array(solve, dtype=int),
        root,
        bool(base),
        np.array([m.jnt_qposadr[j] for j in limited], dtype=int),
        np.array([m.jnt_range[j, 0] for j in limited]),
        np.array([m.jnt_range[j, 1] for j in limited]),
    )
