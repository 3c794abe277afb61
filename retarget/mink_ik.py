"""Per-frame differential IK with mink (the GMR-style alternative to the batched solver).

Same targets as :mod:`retarget.solver` (refined keypoints, stance locks, orientations,
posture prior), solved frame by frame: one ``FrameTask`` per keypoint on a site added at the
keypoint's offset, a ``PostureTask`` on the joints, ``ConfigurationLimit`` passed **by
keyword** (``limits=``; a positional list lands in ``safety_break``), ``daqp`` as QP solver,
up to ``max_iterations`` IK steps per frame while the task error still drops, warm-started
from the previous frame. Segment vectors, the floor margin and the temporal terms of the
batched solver have no per-frame equivalent here. Needs the optional packages ``mink`` and
``daqp`` (``pip install -e ".[bench]"``).
"""

from __future__ import annotations

import time
from types import ModuleType

import mujoco
import numpy as np

from controlmm.errors import ControlMMError
from retarget.reference import initial_guess
from retarget.robot_files import read_robot_mjcf
from retarget.robot_model import RobotModel
from retarget.solver import Solution
from retarget.solver_config import SolverConfig
from retarget.targets import Targets


def _mink() -> ModuleType:
    try:
        import mink  # noqa: F401 - optional package (the "bench" extra): imported only when asked for
    except ImportError:
        raise ControlMMError(
            "the mink solver needs the packages 'mink' and 'daqp' (pip install -e \".[bench]\")"
        ) from None
    return mink


def _model_with_sites(robot: RobotModel) -> mujoco.MjModel:
    """The robot MJCF with one site per keypoint (``kp_<joint>``) at its offset."""
    spec = read_robot_mjcf(robot.mjcf)
    for name, node, off in zip(robot.keypoint_names, robot.nodes, robot.offsets, strict=True):
        body = robot.model.body(int(robot.tree.node_body[node])).name
        spec.body(body).add_site(name=f"kp_{name}", pos=off.tolist())
    return spec.compile()


def solve_mink(
    robot: RobotModel,
    targets: Targets,
    max_iterations: int = 10,
    tolerance: float = 1e-4,
    damping: float = 1e-3,
    solver: str = "daqp",
) -> Solution:
    """Per-frame mink IK on ``targets``; returns a :class:`Solution` like the batched solver."""
    mink = _mink()
    start = time.perf_counter()
    weights = SolverConfig()  # the batched solver's default orientation and posture scales
    model = _model_with_sites(robot)
    config = mink.Configuration(model)
    tasks, frame_tasks = [], []
    for kp in robot.mapping.keypoints:
        task = mink.FrameTask(
            f"kp_{kp.joint}", "site", position_cost=1.0, orientation_cost=0.0, lm_damping=1.0
        )
        frame_tasks.append(task)
        tasks.append(task)
    ori_of = {int(k): i for i, k in enumerate(targets.ori_kp)}
    posture = mink.PostureTask(
        model, cost=np.concatenate([np.zeros(6), np.sqrt(robot.posture_weights) * weights.l_posture])
    )
    rest = np.concatenate([np.zeros(3), [1.0, 0, 0, 0], robot.rest_q])
    posture.set_target(rest)
    tasks.append(posture)
    limits = [mink.ConfigurationLimit(model)]
    root_pos, root_rot, q = initial_guess(robot, targets)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, root_rot[0].reshape(-1))
    config.update(np.concatenate([root_pos[0], quat, np.clip(q[0], robot.lower, robot.upper)]))
    t_len = len(targets.kp_pos)
    out_q = np.empty((t_len, model.nq))
    solves = 0
    for t in range(t_len):
        for k, task in enumerate(frame_tasks):
            w = targets.kp_weight[t, k]
            rot = np.eye(3)
            o = ori_of.get(k)
            ocost = 0.0
            if o is not None:
                rot = targets.ori_rot[t, o]
                ocost = weights.l_rot * np.sqrt(targets.ori_weight[t, o] * targets.ori_axis_weight[o])
            task.set_position_cost(np.sqrt(w))
            task.set_orientation_cost(ocost)
            task.set_target(
                mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rot), targets.kp_pos[t, k])
            )
        for _ in range(max_iterations):
            vel = mink.solve_ik(config, tasks, dt=1.0, solver=solver, damping=damping, limits=limits)
            config.integrate_inplace(vel, 1.0)
            solves += 1
            if np.linalg.norm(vel) < tolerance:  # the step (rad, m) became negligible
                break
        out_q[t] = config.q
    joints = np.clip(out_q[:, 7:], robot.lower, robot.upper)
    rot = np.empty((t_len, 3, 3))
    for t in range(t_len):
        m9 = np.empty(9)
        mujoco.mju_quat2Mat(m9, out_q[t, 3:7] / np.linalg.norm(out_q[t, 3:7]))
        rot[t] = m9.reshape(3, 3)
    return Solution(
        root_pos=out_q[:, 0:3].copy(),
        root_rot=rot,
        q=joints,
        iterations=solves,
        cost=float("nan"),
        seconds=time.perf_counter() - start,
    )
