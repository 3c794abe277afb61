"""Inverse-dynamics feasibility and PD-tracking replay on the real G1/H1 models."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
from sim_motions import (
    FPS,
    adr,
    g1_bare,
    g1_squat_pose,
    h1_stand,
    h1_world,
    hold,
    lean_about_toes,
    plant,
    smooth_blend,
    with_joints,
)

from sim import CheckConfig, check_trajectory
from sim.tracking import _tracking_model
from sim.worlds import standing_qpos


def g1_q0() -> np.ndarray:
    return standing_qpos(g1_bare().model)


def test_static_stand_is_carried_by_the_feet():
    w = g1_bare()
    report = check_trajectory(w, hold(g1_q0(), 5), FPS)
    assert report.passed
    mg = w.mass * 9.81
    dyn = report.dynamics
    np.testing.assert_allclose(dyn.support_force, np.tile([0.0, 0.0, mg], (5, 1)), atol=1e-3 * mg)
    assert dyn.residual_force_ratio.max() < 1e-3 and dyn.residual_moment_m.max() < 1e-3
    assert report.residual_force["max_ratio"] < 1e-3
    # H1: torque limits come from its motor actuators' ctrlrange
    h1 = h1_world()
    assert h1.joints.torque_limit[list(h1.joints.names).index("left_knee")] == 300.0
    assert h1.joints.torque_limit[list(h1.joints.names).index("left_ankle")] == 40.0
    assert g1_bare().joints.torque_limit[list(g1_bare().joints.names).index("left_knee_joint")] == 139.0
    assert check_trajectory(h1, hold(h1_stand(), 5), FPS).dynamics.residual_force_ratio.max() < 1e-3


def test_joint_torques_match_a_physics_hold():
    """Hold a squat with PD servos in mj_step; the settled servo torques equal the inverse
    dynamics torques with the contact forces the check distributes."""
    w = g1_bare()
    squat = plant(w, g1_squat_pose()[None], g1_q0())[0]
    m = _tracking_model(w)
    d = mujoco.MjData(m)
    d.qpos[:] = squat
    J = w.joints
    torques = []
    for k in range(2000):
        tau = 500.0 * (squat[J.qpos_adr] - d.qpos[J.qpos_adr]) - 10.0 * d.qvel[J.dof_adr]
        d.qfrc_applied[J.dof_adr] = np.clip(tau, -J.torque_limit, J.torque_limit)
        mujoco.mj_step(m, d)
        if k >= 1500:
            torques.append(d.qfrc_applied[J.dof_adr].copy())
    assert np.abs(d.qvel).max() < 1e-3  # settled
    report = check_trajectory(w, hold(d.qpos.copy(), 3), FPS)
    assert report.passed
    # sagittal joints: their torques are fixed by the (symmetric) load; roll/yaw joints also
    # carry the internal left-right squeeze, which statics leaves undetermined
    sagittal = [i for i, n in enumerate(J.names) if "pitch" in n or "knee" in n or "elbow" in n]
    np.testing.assert_allclose(
        report.dynamics.joint_torque[1, sagittal], np.mean(torques, axis=0)[sagittal], atol=0.05
    )
    knee = J.names.index("left_knee_joint")
    assert abs(report.dynamics.joint_torque[1, knee]) > 20.0  # the knees do carry the body


def test_holding_an_arm_out_needs_the_gravity_moment():
    w = g1_bare()
    m = w.model
    reach = with_joints(
        m, g1_q0(), left_shoulder_pitch_joint=-1.5708, left_shoulder_roll_joint=0.0, left_elbow_joint=1.5708
    )
    report = check_trajectory(w, hold(reach, 3), FPS)
    d = mujoco.MjData(m)
    d.qpos[:] = reach
    mujoco.mj_forward(m, d)
    joint = m.joint("left_shoulder_pitch_joint").id
    body = m.body("left_shoulder_pitch_link").id
    lever = d.subtree_com[body] - d.xanchor[joint]
    gravity_moment = np.cross(lever, [0.0, 0.0, -9.81 * m.body_subtreemass[body]]) @ d.xaxis[joint]
    torque = report.dynamics.joint_torque[1, w.joints.names.index("left_shoulder_pitch_joint")]
    assert torque == pytest.approx(-gravity_moment, rel=1e-6)
    assert abs(torque) > 4.0


def test_floating_robot_needs_a_hand_of_god():
    w = g1_bare()
    q0 = g1_q0()
    up = q0.copy()
    up[2] += 0.10
    q = np.concatenate(
        [hold(q0, 10), smooth_blend(q0, up, 6), hold(up, 30), smooth_blend(up, q0, 6), hold(q0, 8)]
    )
    report = check_trajectory(w, q, FPS)
    ratio = report.frames["residual_force_ratio"]
    hover = slice(18, 44)
    np.testing.assert_allclose(ratio[hover], 1.0, atol=1e-6)  # the whole weight, at the CoM
    assert report.frames["residual_moment_m"][hover].max() < 1e-6
    assert ratio[:10].max() < 1e-3 and ratio[-3:].max() < 1e-3
    hits = report.failures_of("residual_force")
    assert any(f.frame_start <= 18 and f.frame_end >= 43 for f in hits)


def test_ballistic_jump_is_feasible():
    w = g1_bare()
    q = hold(g1_q0(), 46)
    t = np.arange(16) / FPS
    q[15:31, 2] += 9.81 * 0.15 * t - 0.5 * 9.81 * t**2  # 0.3 s of free flight, lands on frame 30
    report = check_trajectory(w, q, FPS)
    assert report.passed, report.summary()
    assert report.frames["flight"].any()
    # in the air gravity alone explains the motion: no residual
    assert report.frames["residual_force_ratio"][17:29].max() < 1e-6


def test_accelerating_root_exceeds_friction():
    """The standing robot shaken sideways at up to 1 g: the feet (mu 0.6) cannot push that hard."""
    w = g1_bare()
    t = np.arange(100) / FPS
    omega = np.sqrt(9.81 / 0.1)
    q = hold(g1_q0(), 100)
    q[:, 1] += 0.1 * np.sin(omega * t)
    report = check_trajectory(w, q, FPS)
    accel = np.abs(-0.1 * omega**2 * np.sin(omega * t)) / 9.81
    ratio = report.frames["residual_force_ratio"]
    assert report.failures_of("residual_force")
    assert ratio[accel > 0.9].min() > 0.2
    assert ratio[(accel < 0.3)][2:-2].max() < 0.1  # within the friction cone: no residual
    assert report.stats["residual_force"]["max_N"] == pytest.approx(ratio.max() * w.mass * 9.81, rel=1e-3)


def test_leaning_past_the_toes_is_flagged_standing_is_not():
    w = g1_bare()
    q0 = g1_q0()
    lean = lean_about_toes(w, q0, 20.0, 25)
    q = np.concatenate([hold(q0, 5), lean, hold(lean[-1], 20)])
    report = check_trajectory(w, q, FPS)
    assert not report.failures_of("floor_penetration") and not report.failures_of("floating")
    hits = report.failures_of("residual_force") + report.failures_of("residual_moment")
    assert any(f.frame_start <= 31 and f.frame_end == 49 for f in hits)  # the held lean
    assert all(f.frame_start >= 5 for f in hits)
    # a slight lean keeps the centre of mass over the feet
    small = lean_about_toes(w, q0, 3.0, 25)
    q = np.concatenate([hold(q0, 5), small, hold(small[-1], 10)])
    assert check_trajectory(w, q, FPS).passed


def test_fast_arm_swing_exceeds_the_arm_torque_limits():
    w = g1_bare()
    t = np.arange(60) / FPS
    q = hold(g1_q0(), 60)
    q[:, adr(w.model, "left_shoulder_pitch_joint")] = 0.2 + 0.6 * np.sin(2 * np.pi * 4.0 * t)
    report = check_trajectory(w, q, FPS)
    hits = report.failures_of("torque_limit")
    assert "left_shoulder_pitch_joint" in {f.joint for f in hits}
    assert all(
        f.joint.startswith("left_") and ("shoulder" in f.joint or "elbow" in f.joint or "wrist" in f.joint)
        for f in hits
    )
    shoulder = max(f.depth for f in hits if f.joint == "left_shoulder_pitch_joint")
    assert 1.5 < shoulder < 6.0  # |torque| / 25 N m
    assert not report.failures_of("joint_velocity")  # 15 rad/s is within 37 rad/s
    # the same swing ten times slower is easy
    slow = hold(g1_q0(), 60)
    slow[:, adr(w.model, "left_shoulder_pitch_joint")] = 0.2 + 0.6 * np.sin(2 * np.pi * 0.4 * t)
    assert check_trajectory(w, slow, FPS).passed


def test_torque_threshold_is_configurable():
    w = g1_bare()
    squat = plant(w, g1_squat_pose()[None], g1_q0())[0]
    q = hold(squat, 4)
    report = check_trajectory(w, q, FPS, CheckConfig(max_torque_ratio=0.15))
    joints = {f.joint for f in report.failures_of("torque_limit")}
    assert {"left_knee_joint", "right_knee_joint"} <= joints
    assert check_trajectory(w, q, FPS).passed


def test_pd_tracking_replay_stays_up_or_falls():
    w = g1_bare()
    q0 = g1_q0()
    config = CheckConfig(tracking=True)
    report = check_trajectory(w, hold(q0, 40), FPS, config)
    tracking = report.stats["tracking"]
    assert report.passed and not tracking["fell"] and tracking["mean_joint_error_rad"] < 0.05
    assert report.frames["tracking_root_height_m"].min() > 0.7
    data = json.loads(report.to_json())
    assert data["tracking"]["fell"] is False and data["tracking"]["fall_frame"] is None
    assert len(data["frames"]["tracking_joint_error_rad"]) == 40
    # starting 25 degrees past the toes, joint servos cannot save it: the root is unactuated
    q = hold(lean_about_toes(w, q0, 25.0, 2)[-1], 50)
    report = check_trajectory(w, q, FPS, config)
    falls = report.failures_of("tracking_fall")
    assert report.stats["tracking"]["fell"] and len(falls) == 1 and falls[0].frame_end == 49
    assert report.stats["tracking"]["time_up_s"] < 1.0


def test_an_arm_inside_an_obstacle_does_not_hold_the_robot():
    from sim_motions import g1_stand, g1_world

    w = g1_world()  # has a shelf at shoulder height in front of the left arm
    q0 = g1_stand()
    reach = with_joints(
        w.model, q0, left_shoulder_pitch_joint=-1.5708, left_shoulder_roll_joint=0.0, left_elbow_joint=1.5708
    )
    q = np.concatenate(
        [hold(q0, 5), smooth_blend(q0, reach, 20), hold(reach, 15), smooth_blend(reach, q0, 20)]
    )
    report = check_trajectory(w, q, FPS)
    assert {f.kind for f in report.failures} == {"obstacle_penetration"}
    assert report.stats["max_torque_ratio"] < 1.0  # the wrist (5 N m) is not loaded by the shelf
    bare = check_trajectory(g1_bare(), q, FPS)  # the same motion with no shelf: same dynamics
    assert report.residual_force["max_ratio"] == pytest.approx(bare.residual_force["max_ratio"], abs=1e-6)
