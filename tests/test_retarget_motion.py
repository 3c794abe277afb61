"""Retarget the real HumanML3D clip to G1 and H1, then check the exported files independently.

The CSV/NPZ are read back and replayed through MuJoCo (``mj_kinematics`` on the Menagerie
models): positions against the scaled human, exact joint limits, floor contact, stance
feet, column and quaternion order, resampling.
"""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

import scenes
import sim
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from retarget import RobotTrajectory, retarget_motion, robot_mjcf, robot_scale
from retarget.human import HUMAN_ANKLE_HEIGHT, HUMAN_HIP_HEIGHT, size_ratio

# Robot bodies that sit on human joints (HumanML3D index), per robot.
BODIES = {
    "g1": {
        "pelvis": 0,
        "left_hip_roll_link": 1,
        "right_hip_roll_link": 2,
        "left_knee_link": 4,
        "right_knee_link": 5,
        "left_ankle_roll_link": 7,
        "right_ankle_roll_link": 8,
        "left_shoulder_roll_link": 16,
        "right_shoulder_roll_link": 17,
        "left_elbow_link": 18,
        "right_elbow_link": 19,
        "left_wrist_yaw_link": 20,
        "right_wrist_yaw_link": 21,
    },
    "h1": {
        "pelvis": 0,
        "left_hip_pitch_link": 1,
        "right_hip_pitch_link": 2,
        "left_knee_link": 4,
        "right_knee_link": 5,
        "left_ankle_link": 7,
        "right_ankle_link": 8,
        "left_shoulder_roll_link": 16,
        "right_shoulder_roll_link": 17,
        "left_elbow_link": 18,
        "right_elbow_link": 19,
    },
}
FEET = {
    "g1": ("left_ankle_roll_link", "right_ankle_roll_link"),
    "h1": ("left_ankle_link", "right_ankle_link"),
}
LIMBS = [(1, 4), (4, 7), (2, 5), (5, 8), (16, 18), (17, 19)]  # thighs, shanks, upper arms (human joints)


@pytest.fixture(scope="module")
def motion(sample_features) -> Motion:
    return Motion.from_features(sample_features, text="HumanML3D 012314")


@pytest.fixture(scope="module")
def exported(motion, tmp_path_factory):
    """Both robots retargeted at 50 Hz and saved: {robot: (trajectory, prefix)}."""
    out = {}
    for robot in ("g1", "h1"):
        traj = retarget_motion(motion, robot=robot, fps=50)
        prefix = tmp_path_factory.mktemp(robot) / "clip"
        traj.save(prefix)
        out[robot] = (traj, prefix)
    return out


def _replay(model, qpos):
    data = mujoco.MjData(model)
    pos = np.empty((len(qpos), model.nbody, 3))
    geom_pos = np.empty((len(qpos), model.ngeom, 3))
    geom_mat = np.empty((len(qpos), model.ngeom, 3, 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pos[t], geom_pos[t] = data.xpos, data.geom_xpos
        geom_mat[t] = data.geom_xmat.reshape(-1, 3, 3)
    return pos, geom_pos, geom_mat


def _lowest(model, geom_pos, geom_mat, body_name):
    """Lowest world z (T,) of a body's collision spheres, capsules and boxes."""
    body = model.body(body_name).id
    lows = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body or not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        z, up, size = geom_pos[:, g, 2], geom_mat[:, g, 2, :], model.geom_size[g]
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            lows.append(z - size[0])
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            lows.append(z - np.abs(up[:, 2]) * size[1] - size[0])
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            lows.append(z - np.abs(up) @ size[:3])
    assert lows, f"no collision primitives on {body_name}"
    return np.min(lows, axis=0)


def _lowest_geom(model, geom_pos, geom_mat, g):
    """Lowest world z (T,) of one sphere, capsule or box geom."""
    z, up, size = geom_pos[:, g, 2], geom_mat[:, g, 2, :], model.geom_size[g]
    kind = model.geom_type[g]
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return z - size[0]
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return z - np.abs(up[:, 2]) * size[1] - size[0]
    assert kind == mujoco.mjtGeom.mjGEOM_BOX, f"geom {g}: unexpected type {kind}"
    return z - np.abs(up) @ size[:3]


def _read_csv(prefix):
    return np.loadtxt(str(prefix) + ".csv", delimiter=",", ndmin=2)


def _human_world(motion, scale, n, fps):
    world = HumanToWorld(scale=scale).to_world(motion.joints.astype(np.float64))
    t = np.arange(n) / fps
    src = np.arange(len(world)) / motion.fps
    flat = world.reshape(len(world), -1)
    return np.stack([np.interp(t, src, flat[:, c]) for c in range(flat.shape[1])], -1).reshape(n, 22, 3)


@pytest.mark.parametrize("robot", ["g1", "h1"])
def test_csv_layout_and_quaternion_order(exported, robot):
    traj, prefix = exported[robot]
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf(robot)))
    rows = _read_csv(prefix)
    with np.load(str(prefix) + ".npz") as npz:
        qpos = npz["qpos"]
        names = [str(n) for n in npz["joint_names"]]
        body_pos = npz["body_pos_w"]
        body_quat = npz["body_quat_w"]
        body_names = [str(n) for n in npz["body_names"]]
        qvel = npz["qvel"]
        assert float(npz["fps"]) == 50.0
    meta = json.loads((prefix.parent / (prefix.name + ".json")).read_text())
    assert rows.shape == (traj.num_frames, model.nq)
    # xyz, quaternion xyzw, then joints in MJCF (qpos) order.
    hinge = [
        model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE
    ]
    assert names == hinge
    assert (
        meta["csv_columns"]
        == ["root_x", "root_y", "root_z", "root_qx", "root_qy", "root_qz", "root_qw"] + hinge
    )
    assert meta["quaternion_order"]["csv"] == "xyzw"
    np.testing.assert_array_equal(rows[:, 0:3], qpos[:, 0:3])
    np.testing.assert_array_equal(rows[:, 3:7], qpos[:, [4, 5, 6, 3]])
    np.testing.assert_array_equal(rows[:, 7:], qpos[:, 7:])
    np.testing.assert_allclose(np.linalg.norm(rows[:, 3:7], axis=1), 1.0, atol=1e-9)
    # The CSV, converted back to wxyz, reproduces the NPZ body poses through MuJoCo.
    qpos_csv = np.concatenate([rows[:, 0:3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)
    pos, _, _ = _replay(model, qpos_csv)
    assert body_names == [model.body(b).name for b in range(1, model.nbody)]
    np.testing.assert_allclose(body_pos, pos[:, 1:], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(body_quat, axis=-1), 1.0, atol=1e-9)
    # qvel: MuJoCo's finite difference of consecutive qpos (central in the interior).
    v = np.zeros(model.nv)
    mujoco.mj_differentiatePos(model, v, 2 / 50, qpos[9], qpos[11])
    np.testing.assert_allclose(qvel[10], v, atol=1e-9)
    assert meta["robot"] == robot and meta["fps"] == 50 and meta["scale"] == pytest.approx(robot_scale(robot))
    assert meta["source_motion"]["frames"] == 170 and "metrics" in meta


@pytest.mark.parametrize("robot", ["g1", "h1"])
def test_limits_floor_and_positions_checked_in_mujoco(exported, motion, robot):
    traj, prefix = exported[robot]
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf(robot)))
    rows = _read_csv(prefix)
    qpos = np.concatenate([rows[:, 0:3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)
    # Joint limits hold exactly (the CSV carries 17 significant digits).
    hinge = [j for j in range(model.njnt) if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
    lo, hi = model.jnt_range[hinge, 0], model.jnt_range[hinge, 1]
    assert np.all(qpos[:, 7:] >= lo) and np.all(qpos[:, 7:] <= hi)
    pos, gpos, gmat = _replay(model, qpos)
    # No foot below the floor (1 mm tolerance), and the feet do reach it.
    lowest = np.stack([_lowest(model, gpos, gmat, f) for f in FEET[robot]])
    assert lowest.min() >= -1e-3
    assert np.mean(lowest.min(axis=0) < 0.005) > 0.5, "a foot should be on the floor most of the time"
    # Keypoints near the scaled human; limb directions follow the human's.
    human = _human_world(motion, robot_scale(robot), len(qpos), 50.0)
    names = list(BODIES[robot])
    robot_pts = pos[:, [model.body(n).id for n in names]]
    human_pts = human[:, list(BODIES[robot].values())]
    err = np.linalg.norm(robot_pts - human_pts, axis=-1)
    bound = {"g1": 0.1, "h1": 0.17}[robot]  # H1's hips are 0.4 m apart: its feet stand wider
    assert err.mean() < bound, f"mean keypoint distance {err.mean():.3f} m"
    pelvis_xy = np.linalg.norm(robot_pts[:, 0, :2] - human_pts[:, 0, :2], axis=-1)
    assert pelvis_xy.mean() < 0.06
    idx = {j: names.index(n) for n, j in BODIES[robot].items()}
    for a, b in LIMBS:
        u = robot_pts[:, idx[b]] - robot_pts[:, idx[a]]
        w = human_pts[:, idx[b]] - human_pts[:, idx[a]]
        cos = np.sum(u * w, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(w, axis=-1)
        angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        # The upper arms of a hanging arm are abducted on purpose (the mapping's arm_abduction,
        # G1/H1 hips are wider than the scaled human's: see docs/retargeting.md). The knees go
        # under the human's: H1's thighs start 0.4 m apart (the human's 0.12 m) and turn in by
        # up to asin(0.14 / 0.4) = 20 degrees to get there (G1's, 0.23 m against 0.09: 10 on
        # this clip, within the general bound).
        bound = 12 + (np.degrees(traj.robot_model().mapping.arm_abduction) if a in (16, 17) else 0)
        if robot == "h1" and a in (1, 2):
            bound = 20
        assert angle.mean() < bound, f"limb {a}->{b}: mean direction error {angle.mean():.1f} deg"


def _foot_geoms(model, body_name):
    body = model.body(body_name).id
    return [
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]


@pytest.mark.parametrize("robot", ["g1", "h1"])
def test_stance_feet_stay_in_place(exported, robot):
    """The contact does not slip: the feet roll (heel strike, toe-off), so the ankle body may
    move over a planted toe; what must stay put is the collision geom that is on the floor."""
    traj, prefix = exported[robot]
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf(robot)))
    rows = _read_csv(prefix)
    qpos = np.concatenate([rows[:, 0:3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)
    pos, gpos, gmat = _replay(model, qpos)
    stances = 0
    for foot in FEET[robot]:
        geoms = _foot_geoms(model, foot)
        low = np.stack([_lowest_geom(model, gpos, gmat, g) for g in geoms], axis=1)  # (T, G)
        down = (low[:-1] <= 0.005) & (low[1:] <= 0.005)
        step = np.linalg.norm(np.diff(gpos[:, geoms, :2], axis=0), axis=2)
        slide = np.where(down, step, np.inf).min(axis=1)  # the geom that stayed down moved least
        contact = np.isfinite(slide)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], contact.astype(int), [0]])))
        for s, e in zip(edges[::2], edges[1::2], strict=True):
            # H1's 5-joint legs (no ankle roll) cannot hold a foot flat and still in every pose.
            assert slide[s:e].max() < {"g1": 0.004, "h1": 0.01}[robot], (
                f"{foot} slid {slide[s:e].max() * 1000:.1f} mm in one frame"
            )
            stances += 1
        for i, g in enumerate(geoms):  # each geom, while it stays down, stays where it touched
            runs = np.flatnonzero(np.diff(np.concatenate([[0], down[:, i].astype(int), [0]])))
            for s, e in zip(runs[::2], runs[1::2], strict=True):
                drift = np.linalg.norm(gpos[s : e + 1, g, :2] - gpos[s, g, :2], axis=1).max()
                assert drift < {"g1": 0.01, "h1": 0.03}[robot], (
                    f"{foot} slid {drift * 1000:.1f} mm in a stance"
                )
    assert stances >= 6  # the clip has several steps per foot


def test_resampling_rates_and_smoothness(motion, exported):
    traj50, _ = exported["g1"]
    traj30 = retarget_motion(motion, robot="g1", fps=30, metrics=False)
    duration = (motion.num_frames - 1) / motion.fps
    assert traj50.num_frames == int(np.floor(duration * 50)) + 1 == 423
    assert traj30.num_frames == int(np.floor(duration * 30)) + 1
    # Both are resamplings of one solution, then the feet are corrected at the output rate
    # (swing feet lifted straight up where a toe would skim the floor between the motion's
    # frames, the root raised where a foot would sink). Where the time grids meet: the root's
    # horizontal place and orientation and every non-leg joint agree exactly; the feet agree
    # horizontally and, vertically, within the reported lifts.
    a, b = traj30.qpos[::3], traj50.qpos[::5][: len(traj30.qpos[::3])]
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf("g1")))
    legs = [7 + i for i, n in enumerate(traj50.joint_names) if any(k in n for k in ("hip", "knee", "ankle"))]
    same = [c for c in range(model.nq) if c not in legs and c != 2]
    np.testing.assert_allclose(a[:, same], b[:, same], atol=1e-9)
    lift = max(t.solver["floor_lift_max_mm"] + t.solver["swing_lift_max_mm"] for t in (traj30, traj50)) / 1000
    assert np.abs(a[:, 2] - b[:, 2]).max() <= lift + 1e-9
    feet = [model.body(f).id for f in FEET["g1"]]
    pa, pb = _replay(model, a)[0][:, feet], _replay(model, b)[0][:, feet]
    assert np.linalg.norm(pa[..., :2] - pb[..., :2], axis=-1).max() < 0.005
    assert np.abs(pa[..., 2] - pb[..., 2]).max() <= lift + 1e-3
    q = traj50.qpos[:, 7:]
    assert np.abs(np.diff(q, axis=0)).max() * 50 < 15.0  # rad/s
    quat = traj50.qpos[:, 3:7]
    assert np.all(np.sum(quat[1:] * quat[:-1], axis=1) > 0.99)  # continuous hemisphere, no flips


def test_trajectory_load_round_trip(exported):
    traj, prefix = exported["g1"]
    back = RobotTrajectory.load(str(prefix) + ".npz")
    np.testing.assert_array_equal(back.qpos, traj.qpos)
    assert back.fps == traj.fps and back.joint_names == traj.joint_names and back.robot == "g1"
    assert back.scale == pytest.approx(traj.scale) and back.transform == traj.transform
    assert back.metrics["joint_limit_violations"] == 0
    np.testing.assert_array_equal(back.stance, traj.stance)


def test_metrics_report_the_required_figures(exported):
    metrics = exported["g1"][0].metrics
    assert set(metrics["keypoint_error_mm"]) >= {"feet", "hands", "pelvis", "head", "all"}
    assert metrics["joint_limit_violations"] == 0
    assert metrics["floor_penetration_max_mm"] <= 1.0
    assert metrics["foot_sliding_mm_per_stance"]["max"] < 15
    assert metrics["stances"] >= 6 and metrics["joint_jerk_rms_rad_s3"] > 0


def test_transform_places_the_robot(motion):
    """The HumanToWorld given is where the robot goes (yaw and translation)."""
    cropped = Motion(joints=motion.joints[:40], fps=motion.fps)
    scale = robot_scale("g1")
    moved = retarget_motion(
        cropped,
        "g1",
        transform=HumanToWorld(scale=scale, yaw=np.pi / 2, translation=(1.0, 2.0, 0.0)),
        metrics=False,
    )
    human = HumanToWorld(scale=scale, yaw=np.pi / 2, translation=(1.0, 2.0, 0.0)).to_world(
        cropped.joints.astype(float)
    )
    assert np.linalg.norm(moved.qpos[0, :2] - human[0, 0, :2]) < 0.06
    assert moved.transform.yaw == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("start", [0, 20, 40])
def test_landing_feet_do_not_skim_the_floor(sample_joints, start):
    """6 s windows of the clip (the batch benchmark's jobs) at 50 fps: the simulation check
    finds no stance foot sliding. The window from frame 40 lands its right heel while the
    lifted toe hangs still (the slowest sole point is high): the landing heel, 4 mm above the
    floor and moving 0.29 m/s, must be lifted until it slows down."""
    joints = sample_joints[start : start + 120].astype(float)
    traj = retarget_motion(Motion(joints=joints, fps=20), "g1", fps=50.0, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 50.0)
    slides = [f for f in report.failures if f.kind == "foot_sliding"]
    assert not slides, slides


def test_a_hand_near_its_own_shoulder_keeps_clear(sample_joints):
    """The window from frame 19 starts with the right hand by the right shoulder: the hand keeps
    clear of its own shoulder links (they met by 7.7 mm before the hand-shoulder pairs)."""
    joints = sample_joints[19:139].astype(float)
    traj = retarget_motion(Motion(joints=joints, fps=20), "g1", fps=50.0, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot="g1"), traj.qpos, 50.0)
    assert report.stats["self_collision_frames"] == 0, [
        f for f in report.failures if f.kind == "self_collision"
    ]


def test_a_landing_foot_is_lifted_with_the_hip_at_its_limit(sample_joints):
    """T1 on the clip at 30 fps: the right foot lands with its hip pitch at the -1.8 rad stop.
    The lift that keeps a moving foot off the floor solves without the joints at their limits
    (the others make up for them): no stance foot slides (it skimmed in by 39 mm before)."""
    traj = retarget_motion(Motion(joints=sample_joints.astype(float), fps=20), "t1", fps=30.0, metrics=False)
    report = sim.check_trajectory(scenes.load_scene("empty", robot="t1"), traj.qpos, 30.0)
    slides = [f for f in report.failures if f.kind == "foot_sliding"]
    assert not slides, slides


def test_a_recorded_subject_is_scaled_by_its_own_legs(sample_joints):
    """A clip on the HumanML3D skeleton keeps the robot's scale; the same clip 12 % larger (a
    taller subject, its floor kept) is retargeted at a proportionally smaller scale, so the
    robot crouches as deep as for the original."""
    joints = sample_joints.astype(np.float64)
    assert size_ratio(joints) == 1.0
    assert size_ratio(joints * 1.01) == 1.0  # within the tolerance: the reference skeleton
    big = joints * 1.12
    leg = HUMAN_HIP_HEIGHT - HUMAN_ANKLE_HEIGHT
    assert size_ratio(big) == pytest.approx(HUMAN_HIP_HEIGHT / (1.12 * leg + HUMAN_ANKLE_HEIGHT), rel=1e-3)
    base = retarget_motion(Motion(joints=joints, fps=20), "g1", fps=20.0, metrics=False)
    tall = retarget_motion(Motion(joints=big, fps=20), "g1", fps=20.0, metrics=False)
    assert base.scale == pytest.approx(robot_scale("g1"))
    assert tall.scale == pytest.approx(robot_scale("g1") * size_ratio(big))
    # The pelvis height over the clip follows the same crouches at the robot's size.
    np.testing.assert_allclose(tall.qpos[:, 2], base.qpos[:, 2], atol=0.03)
