"""Kinematic replay check on real Menagerie robots: each failure kind on a trajectory built to
have it (right body, geom, frames, depth) and none on clean standing/squatting."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest
from sim_motions import (
    FPS,
    adr,
    g1_squat,
    g1_stand,
    g1_world,
    h1_stand,
    h1_world,
    hold,
    rotate_about,
    smooth_blend,
    with_joints,
)

from sim import CheckConfig, check_trajectory, make_world
from sim.worlds import Obstacle, robot_world, standing_qpos

KIN = CheckConfig(dynamics=False)


def kinds(report) -> set[str]:
    return {f.kind for f in report.failures}


def true_depths(world, qpos: np.ndarray, other: int, mocap=None) -> np.ndarray:
    """Independent truth: deepest overlap of any robot geom with geom ``other`` per frame."""
    m = world.model
    d = mujoco.MjData(m)
    out = np.zeros(len(qpos))
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        if mocap is not None:
            mocap(d, t / FPS)
        mujoco.mj_kinematics(m, d)
        dist = min(mujoco.mj_geomDistance(m, d, int(g), other, 1.0, None) for g in world.robot_geoms)
        out[t] = max(-dist, 0.0)
    return out


def test_clean_stand_and_squat_pass():
    for q in (hold(g1_stand(), 20), g1_squat()):
        report = check_trajectory(g1_world(), q, FPS)
        assert report.passed, report.summary()
        assert report.floor_penetration_m < 0.005 and report.max_penetration_m == 0.0
        assert report.self_collision_frames == 0 and report.foot_sliding_m < 1e-9
        assert report.frames["supported"].all() and not report.frames["floating"].any()
    report = check_trajectory(h1_world(), hold(h1_stand(), 20), FPS)
    assert report.passed, report.summary()


def test_world_classification_and_feet():
    w = g1_world()
    m = w.model
    assert [w.geom_label(g) for g in w.floor_geoms] == ["floor"]
    assert sorted(w.geom_label(g) for g in w.obstacle_geoms) == ["ball", "post", "shelf", "step"]
    assert [f.name for f in w.feet] == ["left_ankle_roll_link", "right_ankle_roll_link"]
    assert all(m.geom_type[f.geoms].tolist() == [2] * 4 for f in w.feet)  # four sole spheres
    assert w.robot_geoms.size == 36 and abs(w.mass - 33.34) < 0.01
    assert [f.name for f in h1_world().feet] == ["left_ankle_link", "right_ankle_link"]


def test_arm_pushed_into_shelf():
    w = g1_world()
    q0 = g1_stand()
    reach = with_joints(
        w.model, q0, left_shoulder_pitch_joint=-1.5708, left_shoulder_roll_joint=0.0, left_elbow_joint=1.5708
    )
    q = np.concatenate(
        [hold(q0, 5), smooth_blend(q0, reach, 20), hold(reach, 15), smooth_blend(reach, q0, 20)]
    )
    report = check_trajectory(w, q, FPS, KIN)
    shelf = w.model.geom("shelf").id
    truth = true_depths(w, q, shelf)
    hits = report.failures_of("obstacle_penetration")
    assert hits and {f.obstacle_geom for f in hits} == {"shelf"}
    assert {f.robot_body for f in hits} <= {
        "left_elbow_link",
        "left_wrist_roll_link",
        "left_wrist_pitch_link",
        "left_wrist_yaw_link",
        "left_shoulder_yaw_link",
    }
    assert "left_wrist_yaw_link" in {f.robot_body for f in hits}
    flagged = np.zeros(len(q), dtype=bool)
    for f in hits:
        flagged[f.frame_start : f.frame_end + 1] = True
    np.testing.assert_array_equal(flagged, truth > 0.005)
    assert not flagged[:5].any() and flagged[25:40].all()  # clear at rest, inside while the arm is held out
    assert report.max_penetration_m == pytest.approx(truth.max(), abs=1e-3)
    assert 0.02 < report.max_penetration_m < 0.12
    assert np.nanmin(report.frames["clearance_m"]) == pytest.approx(-truth.max(), abs=1e-3)
    bodies = [w.body_name(b) for b in w.robot_bodies]
    clearance = report.kinematic.body_clearance
    assert np.nanmin(clearance[:, bodies.index("left_wrist_yaw_link")]) < -0.005
    assert np.isnan(clearance[:, bodies.index("right_knee_link")]).all()  # never within 10 cm
    assert kinds(report) == {"obstacle_penetration"}


def test_moving_mocap_ball_hits_the_legs():
    w = g1_world()
    ball = w.model.body("ball").mocapid[0]

    def set_time(data, t):  # the ball rolls along y through the knees at 1 m/s
        data.mocap_pos[ball] = (0.0, 1.0 - t, 0.45)

    q = hold(g1_stand(), 100)
    report = check_trajectory(w.model, q, FPS, KIN, set_time=set_time)
    truth = true_depths(w, q, w.model.geom("ball").id, mocap=set_time)
    hits = report.failures_of("obstacle_penetration")
    assert hits and {f.obstacle_geom for f in hits} == {"ball"}
    assert {f.robot_body for f in hits} <= {
        f"{s}_{b}"
        for s in ("left", "right")
        for b in ("knee_link", "hip_yaw_link", "hip_roll_link", "ankle_pitch_link")
    }
    flagged = np.zeros(len(q), dtype=bool)
    for f in hits:
        flagged[f.frame_start : f.frame_end + 1] = True
    np.testing.assert_array_equal(flagged, truth > 0.005)
    assert report.max_penetration_m == pytest.approx(truth.max(), abs=1e-3)
    # without the callback the ball stays parked at y = 3 m and nothing is hit
    assert check_trajectory(w.model, q, FPS, KIN).passed


def test_pose_sunk_into_floor():
    w = g1_world()
    q0 = g1_stand()
    low = q0.copy()
    low[2] -= 0.03
    q = np.concatenate(
        [hold(q0, 20), smooth_blend(q0, low, 6), hold(low, 20), smooth_blend(low, q0, 6), hold(q0, 8)]
    )
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("floor_penetration")
    assert {f.robot_body for f in hits} == {"left_ankle_roll_link", "right_ankle_roll_link"}
    assert {f.obstacle_geom for f in hits} == {"floor"}
    sink = q0[2] - q[:, 2] + 0.00186  # the stand keyframe is 1.86 mm deep already
    expected = np.flatnonzero(sink > 0.005)
    for f in hits:
        assert (f.frame_start, f.frame_end) == (expected[0], expected[-1])
        assert f.depth == pytest.approx(0.03186, abs=3e-4)
    assert report.floor_penetration_m == pytest.approx(0.03186, abs=3e-4)
    assert np.nanmin(report.frames["lowest_height_m"]) == pytest.approx(-0.03186, abs=3e-4)
    assert kinds(report) == {"floor_penetration"}


def _crossing_arms(world) -> np.ndarray:
    q0 = g1_stand()
    cross = with_joints(world.model, q0, left_shoulder_roll_joint=-1.5, right_shoulder_roll_joint=1.5)
    return np.concatenate(
        [hold(q0, 10), smooth_blend(q0, cross, 20), hold(cross, 10), smooth_blend(cross, q0, 20)]
    )


def test_arms_crossing_the_torso_self_collide():
    w = g1_world()
    q = _crossing_arms(w)
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("self_collision")
    pairs = {(f.robot_body, f.obstacle_geom) for f in hits}
    assert ("torso_link", "left_shoulder_yaw_link") in pairs and (
        "torso_link",
        "right_shoulder_yaw_link",
    ) in pairs
    torso = [f for f in hits if f.robot_body == "torso_link" and f.obstacle_geom == "left_shoulder_yaw_link"]
    assert (
        len(torso) == 1 and torso[0].frame_start <= 30 <= 39 <= torso[0].frame_end and torso[0].depth > 0.05
    )
    assert not report.failures_of("obstacle_penetration") and not report.failures_of("floor_penetration")
    # the self-collision check can be switched off
    assert not check_trajectory(w, q, FPS, CheckConfig(dynamics=False, self_collision="off")).failures_of(
        "self_collision"
    )


def test_exclusions_and_parent_filter_are_honoured():
    # H1's MJCF excludes torso <-> shoulder-roll links; with the arms raised overhead their
    # colliders overlap by about 1 cm.
    w = h1_world()
    q0 = h1_stand()
    up = with_joints(
        w.model,
        q0,
        left_shoulder_pitch=-2.8,
        left_shoulder_roll=0.57,
        right_shoulder_pitch=-2.8,
        right_shoulder_roll=-0.57,
    )
    q = np.concatenate([hold(q0, 3), smooth_blend(q0, up, 10), hold(up, 5)])
    excluded = {("torso_link", "left_shoulder_roll_link"), ("torso_link", "right_shoulder_roll_link")}
    assert w.model.nexclude == 2

    def pairs(model):
        return {
            (f.robot_body, f.obstacle_geom)
            for f in check_trajectory(model, q, FPS, KIN).failures_of("self_collision")
        }

    assert not pairs(w.model) & excluded
    unexcluded = copy.deepcopy(w.model)
    unexcluded.exclude_signature[:] = 0
    assert pairs(unexcluded) >= excluded
    # an <exclude> added to G1 removes exactly that pair
    spec = mujoco.MjSpec.from_file(str(__import__("retarget").robots.robot_mjcf("g1")))
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    spec.add_exclude(bodyname1="torso_link", bodyname2="left_shoulder_yaw_link")
    pairs = {
        (f.robot_body, f.obstacle_geom)
        for f in check_trajectory(spec.compile(), _crossing_arms(g1_world()), FPS, KIN).failures_of(
            "self_collision"
        )
    }
    assert ("torso_link", "left_shoulder_yaw_link") not in pairs
    assert ("torso_link", "right_shoulder_yaw_link") in pairs
    # MuJoCo's parent-child filter: off in the model -> adjacent links collide at rest
    nofilter = copy.deepcopy(g1_world().model)
    nofilter.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
    assert check_trajectory(nofilter, hold(g1_stand(), 2), FPS, KIN).self_collision_frames == 2


def test_capsule_colliders_keep_real_self_collisions():
    w = g1_world()
    report = check_trajectory(
        w, _crossing_arms(w), FPS, CheckConfig(dynamics=False, self_collision="capsules")
    )
    pairs = {(f.robot_body, f.obstacle_geom) for f in report.failures_of("self_collision")}
    assert ("torso_link", "left_shoulder_yaw_link") in pairs
    assert check_trajectory(w, g1_squat(), FPS, CheckConfig(dynamics=False, self_collision="capsules")).passed


def test_joint_limit_violation():
    w = g1_world()
    q0 = g1_stand()
    over = with_joints(w.model, q0, left_elbow_joint=2.2)  # range -1.0472 .. 2.0944
    q = np.concatenate([hold(q0, 10), smooth_blend(q0, over, 15), hold(over, 10), smooth_blend(over, q0, 15)])
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("joint_limit")
    elbow = q[:, adr(w.model, "left_elbow_joint")]
    expected = np.flatnonzero(elbow > 2.0944 + 1e-4)
    assert len(hits) == 1
    f = hits[0]
    assert (f.joint, f.robot_body) == ("left_elbow_joint", "left_elbow_link")
    assert (f.frame_start, f.frame_end) == (expected[0], expected[-1])
    assert f.depth == pytest.approx(2.2 - 2.0944, abs=1e-4)
    assert report.joint_limit_violations == expected.size
    assert np.nanmin(report.frames["joint_limit_margin_rad"]) == pytest.approx(-(2.2 - 2.0944), abs=1e-4)
    assert kinds(report) == {"joint_limit"}


def test_joint_velocity_spike():
    w = g1_world()
    q = hold(g1_stand(), 30)
    q[15:, adr(w.model, "left_elbow_joint")] -= 1.0  # 1 rad in one frame = 50 rad/s > 37 rad/s
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("joint_velocity")
    assert [(f.joint, f.frame_start, f.frame_end) for f in hits] == [("left_elbow_joint", 14, 15)]
    assert hits[0].depth == pytest.approx(50.0 - 37.0, abs=1e-6)
    # the same jump spread over 3 frames is within the limit
    q[14, adr(w.model, "left_elbow_joint")] -= 0.5
    assert not check_trajectory(w, q, 30.0, KIN).failures_of("joint_velocity")


def test_stance_feet_sliding():
    w = g1_world()
    q = hold(g1_stand(), 50)
    q[20:41, 0] += 0.5 * np.arange(21) / FPS  # the standing robot glides forward at 0.5 m/s
    q[41:, 0] = q[40, 0]
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("foot_sliding")
    assert {f.robot_body for f in hits} == {"left_ankle_roll_link", "right_ankle_roll_link"}
    for f in hits:
        assert (f.frame_start, f.frame_end) == (21, 40)
        assert f.depth == pytest.approx(0.2, abs=1e-6)  # metres slid over the range
    assert report.foot_sliding_m == pytest.approx(0.4, abs=1e-6)
    assert report.stats["max_foot_slide_speed_mps"] == pytest.approx(0.5, abs=1e-6)
    assert kinds(report) == {"foot_sliding"}
    # a slow creep (0.1 m/s) is below the 0.2 m/s threshold
    q[20:41, 0] = 0.1 * np.arange(21) / FPS
    q[41:, 0] = q[40, 0]
    assert not check_trajectory(w, q, FPS, KIN).failures_of("foot_sliding")


def test_a_box_foot_rolling_over_its_toe_edge_does_not_slide():
    """The T1's feet are one box each: leaning forward over their toe edges moves the boxes'
    centres at over 0.3 m/s while the edges on the floor stay put (no slide); gliding slides."""
    w = make_world(robot_world("t1"))
    m, d = w.model, mujoco.MjData(w.model)
    q0 = standing_qpos(m)
    d.qpos[:] = q0
    mujoco.mj_kinematics(m, d)
    geoms = np.concatenate([f.geoms for f in w.feet])
    assert all(m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX for g in geoms)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    corners = np.concatenate(
        [d.geom_xpos[g] + (signs * m.geom_size[g]) @ d.geom_xmat[g].reshape(3, 3).T for g in geoms]
    )
    toe = corners[np.argmax(corners[:, 0] - 10 * corners[:, 2])]  # the front edge on the floor
    s = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, 10))
    lean = np.stack([rotate_about(q0, toe * [1, 0, 1], np.deg2rad(40.0) * a, w.root_qpos_adr) for a in s])
    q = np.concatenate([hold(q0, 10), lean, hold(lean[-1], 10)])
    centre = []
    for frame in q:
        d.qpos[:] = frame
        mujoco.mj_kinematics(m, d)
        centre.append(d.geom_xpos[geoms[0], :2].copy())
    assert np.linalg.norm(np.diff(centre, axis=0), axis=1).max() * FPS > 0.3  # centres: 0.2 m/s fails
    report = check_trajectory(w, q, FPS, KIN)
    assert report.frames["foot_stance:" + w.feet[0].name][1:20].all()  # (from the second frame)
    assert not report.failures_of("foot_sliding") and report.foot_sliding_m < 1e-6
    glide = hold(q0, 30)
    glide[10:, 0] += 0.5 * np.arange(20) / FPS
    hits = check_trajectory(w, glide, FPS, KIN).failures_of("foot_sliding")
    assert {f.robot_body for f in hits} == {f.name for f in w.feet}
    assert all(f.depth == pytest.approx(19 * 0.5 / FPS, abs=1e-6) for f in hits)  # metres over the range


def test_floating_robot_and_ballistic_flight():
    w = g1_world()
    q0 = g1_stand()
    up = q0.copy()
    up[2] += 0.10
    q = np.concatenate(
        [hold(q0, 20), smooth_blend(q0, up, 6), hold(up, 50), smooth_blend(up, q0, 6), hold(q0, 10)]
    )
    report = check_trajectory(w, q, FPS, KIN)
    hits = report.failures_of("floating")
    lowest = q[:, 2] - q0[2] - 0.00186
    expected = np.flatnonzero(lowest >= 0.02)
    assert len(hits) == 1 and (hits[0].frame_start, hits[0].frame_end) == (expected[0], expected[-1])
    assert hits[0].depth == pytest.approx(0.10 - 0.00186, abs=1e-4)
    assert hits[0].robot_body in {"left_ankle_roll_link", "right_ankle_roll_link"}
    # a jump: 0.3 s of ballistic flight is allowed
    t = np.arange(16) / FPS
    g = 9.81
    z = 1.5 * g * 0.15 / 1.5 * t - 0.5 * g * t**2  # take-off speed g * 0.15 -> lands after 0.3 s
    q = hold(q0, 46)
    q[15:31, 2] += z
    report = check_trajectory(w, q, FPS, KIN)
    assert report.passed, report.summary()
    assert report.frames["flight"].sum() >= 10 and not report.frames["floating"].any()


def test_substeps_catch_an_obstacle_crossed_between_frames():
    # A 1 cm blade at knee height; the robot jumps 0.9 m per frame at 5 fps, so the knees are
    # in front of the blade in one frame and behind it in the next.
    w = make_world(robot_world("g1", [Obstacle("blade", "box", (0.005, 0.5, 0.05), (0.45, 0.0, 0.4))]))
    q = hold(g1_stand(), 3)
    q[:, 0] = (0.0, 0.9, 1.8)
    assert not check_trajectory(w, q, 5.0, KIN).failures_of("obstacle_penetration")
    dense = check_trajectory(w, q, 5.0, CheckConfig(dynamics=False, substeps=9))
    hits = dense.failures_of("obstacle_penetration")
    assert hits and {f.obstacle_geom for f in hits} == {"blade"} and dense.num_frames == 3
