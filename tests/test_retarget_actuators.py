"""Motor limits and joint damping read from the MJCF, the solver keeping damped joints slow, and
joints kept within their speed limits."""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from controlmm.corpus.dataset import ClipSpec, make_clip
from controlmm.motion import Motion
from retarget import SolverConfig, load_robot, retarget_motion
from retarget.actuators import (
    DEFAULT_VELOCITY_LIMIT,
    PUBLISHED_VELOCITY_LIMITS,
    damped_speed_limits,
    damping_share,
    joint_speed_limits,
    joint_torque_limits,
)
from retarget.compare import similarity_fit
from retarget.speed_rungs import SPEED_SPREAD, SPEED_STEP, speed_gain, speed_ratios
from scenes import load_scene
from sim import CheckConfig, check_trajectory
from sim.world import make_world

FPS = 30.0


def _joint(model: mujoco.MjModel, name: str) -> int:
    return int(model.joint(name).id)


def test_torque_limits_and_damping_come_from_the_mjcf():
    apollo = load_robot("apollo").model
    yaw = _joint(apollo, "torso_yaw")
    assert joint_torque_limits(apollo, [yaw])[0] == 120.0  # its actuatorfrcrange
    assert apollo.dof_damping[apollo.jnt_dofadr[yaw]] == 200.0
    assert damping_share(apollo, [yaw])[0] == 200.0 / 120.0
    h1 = load_robot("h1").model  # plain motors: control range x gain x gear
    knee = _joint(h1, "left_knee")
    motor = next(a for a in range(h1.nu) if h1.actuator_trnid[a, 0] == knee)
    expected = np.abs(h1.actuator_ctrlrange[motor]).max() * abs(h1.actuator_gear[motor, 0])
    assert joint_torque_limits(h1, [knee])[0] == expected > 0
    g1 = load_robot("g1")  # no joint damping
    assert np.all(g1.damping_share == 0.0)
    assert np.all(load_robot("apollo").damping_share > 0.0)
    # The solver and the check read the same limits.
    world = make_world(load_scene("empty", robot="apollo").model)
    ids = [_joint(apollo, n) for n in world.joints.names]
    np.testing.assert_array_equal(world.joints.torque_limit, joint_torque_limits(apollo, ids))


def _damping_load(robot, qpos: np.ndarray, joint: str) -> float:
    """Largest 0.5 s mean of |damping * speed| / torque limit of ``joint`` (the share of its
    motor its damping alone takes, as the check averages torques)."""
    model = robot.model
    j = _joint(model, joint)
    speed = np.diff(qpos[:, model.jnt_qposadr[j]]) * FPS
    share = damping_share(model, [j])[0] * np.abs(speed)
    return float(uniform_filter1d(share, int(0.5 * FPS) + 1).max())


def test_a_damped_joint_turns_no_faster_than_its_motor_allows(sample_joints):
    """The real clip turns on the spot; the Apollo's torso yaw (damping 200 N m s/rad, a
    120 N m motor) followed the human's shoulders at 3.6 rad/s, its damping alone four times
    its motor. Weighing the damping's share of the motor halves that; the speed rungs, under
    the speed at which the damping alone takes the whole motor (0.6 rad/s), take it to about
    the motor, the torso lagging the human's turn by up to 6 mm of fit on average (this clip's
    turn is still too fast for the check's torques: a hip yaw carries it, the foot planted)."""
    robot = load_robot("apollo")
    config = SolverConfig(**robot.mapping.solver)
    plain = retarget_motion(
        sample_joints, "apollo", fps=FPS, config=replace(config, w_joint_damping=0.0, speed_limits=False)
    )
    weighed = retarget_motion(sample_joints, "apollo", fps=FPS, config=replace(config, speed_limits=False))
    kept = retarget_motion(sample_joints, "apollo", fps=FPS, config=config)
    yaw = robot.tree.joint_names.index("torso_yaw")
    assert damped_speed_limits(robot.damping_share)[yaw] == pytest.approx(120.0 / 200.0)
    before, halved, after = (_damping_load(robot, t.qpos, "torso_yaw") for t in (plain, weighed, kept))
    assert before > 3.0  # 4.02: the damping alone four times the motor, over half a second
    assert halved < 0.6 * before  # 1.93
    assert after < 0.65 * halved and kept.solver["speed_limit_solves"] >= 1  # 1.13
    # ... the weight with the robot as close to the human as before, the rungs giving up some.
    fits = [similarity_fit(robot, t.qpos, FPS, sample_joints, 20.0).mean for t in (plain, weighed, kept)]
    assert fits[1] < fits[0] + 0.005  # 4.07 -> 4.18 cm
    assert fits[2] < fits[1] + 0.01  # 4.82 cm
    worst = [_torque_errors(t.qpos).get("torso_yaw", 0.0) for t in (plain, weighed, kept)]
    assert worst[0] > 3.0  # the check's sustained torque (damping, inertia, load): 4.21
    assert worst[1] < worst[0] / 1.5  # 1.93
    assert worst[2] < worst[1] / 1.5  # 1.15


def _torque_errors(qpos: np.ndarray) -> dict[str, float]:
    """joint -> the worst sustained torque ratio of the check's torque_limit errors."""
    out: dict[str, float] = {}
    for f in check_trajectory(load_scene("empty", robot="apollo"), qpos, FPS).failures:
        if f.is_error and f.kind == "torque_limit" and f.joint:
            out[f.joint] = max(out.get(f.joint, 0.0), float(f.depth))
    return out


def test_joints_stay_within_their_speed_limits_where_the_human_swings_fast():
    """Apollo raising both arms (the corpus's clip 000019, the upper arms at up to 9.3 rad/s):
    tracked however fast (``speed_limits=False``), an elbow turns 26 % past the 3 pi rad/s that
    ``controlmm validate`` allows a joint without a published limit; by default the speed rungs
    stiffen the too-fast joints' velocity term there until none is past its limit, the check
    finds no joint too fast, and the fit gives up little. The limits are the check's own (one
    table, which sim re-exports), the G1's published ones apart."""
    _, joints, _, _ = make_clip(ClipSpec(19, "000019", "raise_both_arms", "train", 0))
    motion = Motion(joints=joints, fps=20.0)
    robot = load_robot("apollo")
    limits = joint_speed_limits(robot.tree.joint_names)
    assert (
        np.all(limits == DEFAULT_VELOCITY_LIMIT)
        and DEFAULT_VELOCITY_LIMIT == CheckConfig().default_velocity_limit
    )
    assert (
        joint_speed_limits(["left_knee_joint", "robot/left_knee_joint"]).tolist()
        == [PUBLISHED_VELOCITY_LIMITS["left_knee_joint"]] * 2
    )
    free = retarget_motion(motion, robot, fps=FPS, config=replace(SolverConfig(), speed_limits=False))
    traj = retarget_motion(motion, robot, fps=FPS)
    assert speed_ratios(free.qpos, FPS, limits).max() > 1.1 and free.solver["speed_limit_solves"] == 0
    assert traj.solver["speed_limit_solves"] >= 1 and speed_ratios(traj.qpos, FPS, limits).max() <= 1.0
    report = check_trajectory(load_scene("empty", robot="apollo"), traj.qpos, traj.fps)
    assert report.stats["joint_velocity_violations"] == 0, report.summary()
    assert report.stats["self_collision_frames"] == 0 and traj.metrics["joint_limit_violations"] == 0
    fits = [similarity_fit(robot, t.qpos, FPS, motion.joints, motion.fps).mean for t in (free, traj)]
    assert fits[1] < fits[0] + 0.015, fits


def test_speed_gain_stiffens_each_too_fast_joint_near_its_fast_steps():
    """A joint past its limit in one output step (30 fps) gets SPEED_STEP on the solver's
    frames (20 fps) within SPEED_SPREAD of that step, again on a second rung; others keep 1."""
    ratios = np.zeros((59, 3))
    ratios[30, 1] = 1.2  # the step from 1.0 s to 1.033 s
    gain = speed_gain(ratios, 30.0, 40, 20.0, None)
    near = np.abs(np.arange(40) / 20.0 - 30.5 / 30.0) <= SPEED_SPREAD
    assert np.array_equal(gain[:, 1], np.where(near, SPEED_STEP, 1.0)) and np.all(gain[:, [0, 2]] == 1.0)
    again = speed_gain(ratios, 30.0, 40, 20.0, gain)
    assert np.array_equal(again[:, 1], np.where(near, SPEED_STEP**2, 1.0))
