"""Robots by mapping file (a third robot, Booster T1, from a mapping only), scales, bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from controlmm.errors import ControlMMError
from controlmm.frames import HumanToWorld
from controlmm.motion import Motion
from retarget import load_robot, retarget_motion, robot_mjcf, robot_scale
from retarget.robot_model import HUMAN_HIP_HEIGHT

T1_MAPPING = {
    "format": "controlmm-retarget-mapping/1",
    "robot": "t1",
    "keypoints": {
        "pelvis": {"body": "Waist", "offset": [0.015, 0.0, 0.031], "orientation_weight": 2.0},
        "left_hip": {"body": "Hip_Roll_Left"},
        "right_hip": {"body": "Hip_Roll_Right"},
        "left_knee": {"body": "Shank_Left"},
        "right_knee": {"body": "Shank_Right"},
        "left_ankle": {"body": "left_foot_link"},
        "right_ankle": {"body": "right_foot_link"},
        "left_foot": {"body": "left_foot_link", "offset": [0.083, 0.0, -0.028]},
        "right_foot": {"body": "right_foot_link", "offset": [0.083, 0.0, -0.028]},
        "spine3": {"body": "Trunk", "offset": [0.0, 0.0, 0.115]},
        "head": {"body": "H2", "offset": [0.05, 0.0, 0.09]},
        "left_shoulder": {"body": "AL2"},
        "right_shoulder": {"body": "AR2"},
        "left_elbow": {"body": "left_hand_link"},
        "right_elbow": {"body": "right_hand_link"},
        "left_wrist": {"body": "left_hand_link", "offset": [0.0, 0.2, 0.0]},
        "right_wrist": {"body": "right_hand_link", "offset": [0.0, -0.2, 0.0]},
    },
}


def cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "controlmm", *map(str, args)], capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def short_motion(sample_features) -> Motion:
    return Motion.from_features(sample_features[100:160])


def test_packaged_robots_and_scales():
    for robot in ("g1", "h1"):
        model = mujoco.MjModel.from_xml_path(str(robot_mjcf(robot)))
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        rm = load_robot(robot)
        hips = [rm.mapping.keypoint(j).body for j in ("left_hip", "right_hip")]
        hip_z = np.mean([data.xpos[model.body(b).id][2] for b in hips])
        feet = [
            g
            for g in range(model.ngeom)
            if model.geom_contype[g]
            and model.body(model.geom_bodyid[g]).name in (rm.mapping.keypoint("left_ankle").body,)
        ]
        sole = min(
            data.geom_xpos[g][2]
            - (
                model.geom_size[g][0]
                if model.geom_type[g] == 2
                else abs(data.geom_xmat[g][8]) * model.geom_size[g][1] + model.geom_size[g][0]
            )
            for g in feet
        )
        assert robot_scale(robot) == pytest.approx((hip_z - sole) / HUMAN_HIP_HEIGHT, rel=1e-6)
    assert 0.7 < robot_scale("g1") < 0.8 and 0.95 < robot_scale("h1") < 1.05
    # Every body of the robot lists the human joints it follows (for simulation feedback).
    g1 = load_robot("g1")
    assert set(g1.body_joints) == set(g1.body_names)
    assert g1.body_joints["left_knee_link"] == ("left_knee", "left_ankle")


def test_third_robot_from_a_mapping_file_only(tmp_path, short_motion):
    path = tmp_path / "t1.json"
    path.write_text(json.dumps(T1_MAPPING))
    traj = retarget_motion(short_motion, robot=path, fps=50)
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf("t1")))
    assert traj.qpos.shape == (int(np.floor((short_motion.num_frames - 1) / 20 * 50)) + 1, model.nq)
    hinge = [j for j in range(model.njnt) if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
    q = traj.qpos[:, 7:]
    assert np.all(q >= model.jnt_range[hinge, 0]) and np.all(q <= model.jnt_range[hinge, 1])
    data = mujoco.MjData(model)
    foot = model.body("left_foot_link").id
    box = [g for g in range(model.ngeom) if model.geom_bodyid[g] == foot and model.geom_contype[g]][0]
    pelvis_err, lowest = [], []
    human = HumanToWorld(scale=traj.scale).to_world(short_motion.joints.astype(float))
    for t in range(0, traj.num_frames, 5):  # frames 0, 5, 10 ... are the motion's frames 0, 2, 4 ...
        data.qpos[:] = traj.qpos[t]
        mujoco.mj_kinematics(model, data)
        up = data.geom_xmat[box].reshape(3, 3)[2]
        lowest.append(data.geom_xpos[box][2] - np.abs(up) @ model.geom_size[box])
        pelvis_err.append(np.linalg.norm(data.xpos[model.body("Waist").id][:2] - human[2 * t // 5, 0, :2]))
    assert min(lowest) >= -1e-3
    assert np.mean(pelvis_err) < 0.08
    assert traj.metrics["joint_limit_violations"] == 0
    paths = traj.save(tmp_path / "t1_out")
    assert np.loadtxt(paths["csv"], delimiter=",").shape[1] == 7 + len(hinge)
    assert json.loads(paths["json"].read_text())["robot"] == "t1"


def test_bad_inputs_raise_one_line_errors(tmp_path, short_motion):
    with pytest.raises(
        ControlMMError, match="unknown robot 'nao'.*known robots: apollo, berkeley_humanoid, g1, h1"
    ):
        retarget_motion(short_motion, robot="nao")
    bad = dict(T1_MAPPING, keypoints=dict(T1_MAPPING["keypoints"], left_knee={"body": "Knee_Left"}))
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(ControlMMError, match="body 'Knee_Left'"):
        retarget_motion(short_motion, robot=path)
    with pytest.raises(ControlMMError, match=r"shape \(T, 22, 3\)"):
        retarget_motion(np.zeros((10, 21, 3)))
    nan = short_motion.joints.copy()
    nan[3, 4, 1] = np.nan
    with pytest.raises(ControlMMError, match="NaN"):
        retarget_motion(nan)
    one = retarget_motion(short_motion.joints[:1], metrics=False)  # a single frame is a pose
    assert one.qpos.shape == (1, 36)
    for fps in (0, -5, 5000, float("nan")):
        with pytest.raises(ControlMMError, match="fps .* out of range"):
            retarget_motion(short_motion, fps=fps)
    with pytest.raises(ControlMMError, match="unknown solver setting 'iterations'"):
        load_robot(_mapping_file(tmp_path, solver={"iterations": 3}))
    for roll in (1.5, -0.2, "flat"):
        with pytest.raises(ControlMMError, match="solver foot_roll must be a"):
            load_robot(_mapping_file(tmp_path, solver={"foot_roll": roll}))
    assert load_robot(_mapping_file(tmp_path, solver={"foot_roll": 0})).mapping.solver == {"foot_roll": 0.0}
    with pytest.raises(ControlMMError, match="orientation"):
        load_robot(_mapping_with(tmp_path, left_knee={"body": "Shank_Left", "orientation_weight": 1.0}))


def _mapping_file(tmp_path, **fields):
    path = tmp_path / "fields.json"
    path.write_text(json.dumps(dict(T1_MAPPING, **fields)))
    return str(path)


def _mapping_with(tmp_path, **keypoints):
    data = dict(T1_MAPPING, keypoints=dict(T1_MAPPING["keypoints"], **keypoints))
    path = tmp_path / "variant.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_cli_retarget_writes_files_and_reports(tmp_path, humanml3d_dir, sample_features):
    motion = tmp_path / "short.npy"
    np.save(motion, sample_features[:40])
    res = cli("retarget", motion, "--robot", "h1", "--fps", "30", "--out", tmp_path / "h1")
    assert res.returncode == 0, res.stderr
    assert "joint-limit violations        0" in res.stdout and "keypoint error feet" in res.stdout
    rows = np.loadtxt(tmp_path / "h1.csv", delimiter=",")
    assert rows.shape == (int(np.floor(39 / 20 * 30)) + 1, 26)
    meta = json.loads((tmp_path / "h1.json").read_text())
    assert meta["fps"] == 30 and meta["source_motion"]["path"] == str(motion)


def test_cli_bad_input_exits_2_with_one_line(tmp_path, sample_features, capsys):
    from controlmm.cli.main import main

    motion = tmp_path / "short.npy"
    np.save(motion, sample_features[:30])
    nan = tmp_path / "nan.npy"
    arr = sample_features[:30].copy()
    arr[5, 10] = np.nan
    np.save(nan, arr)
    wrong = tmp_path / "wrong.npy"
    np.save(wrong, np.zeros((30, 5)))
    bad_map = tmp_path / "bad.json"
    bad_map.write_text(
        json.dumps(dict(T1_MAPPING, keypoints=dict(T1_MAPPING["keypoints"], head={"body": "Head_Link"})))
    )
    cases = [
        ((motion, "--robot", "nao"), "known robots: apollo, berkeley_humanoid, g1, h1, op3, t1"),
        ((motion, "--robot", bad_map), "Head_Link"),
        ((motion, "--fps", "0"), "out of range"),
        ((motion, "--render", tmp_path / "x.avi"), "allowed: .mp4, .gif"),
        ((nan,), "NaN"),
        ((wrong,), "shape"),
    ]
    for args, needle in cases:
        code = main(["retarget", *map(str, args), "--out", str(tmp_path / "x")])
        err = capsys.readouterr().err
        assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err
    assert not list(tmp_path.glob("x.*"))  # nothing half-written
    res = cli("retarget", motion, "--robot", "nao", "--out", tmp_path / "x")  # the console script itself
    assert res.returncode == 2 and res.stderr.startswith("controlmm: error: unknown robot 'nao'")


def test_cli_render_mujoco_egl_and_stick_fallback(tmp_path, sample_features):
    motion = tmp_path / "short.npy"
    np.save(motion, sample_features[:12])
    small = ("--render-width", "64", "--render-height", "48", "--render-fps", "10")
    env = {**__import__("os").environ, "MUJOCO_GL": "egl"}
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "controlmm",
            "retarget",
            str(motion),
            "--out",
            str(tmp_path / "a"),
            "--render",
            str(tmp_path / "a.mp4"),
            *small,
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert res.returncode == 0, res.stderr
    assert "(mujoco)" in res.stdout and (tmp_path / "a.mp4").stat().st_size > 500
    # OSMesa is not installed on the reference machine: MuJoCo cannot load it -> stick figure.
    env["MUJOCO_GL"] = "osmesa"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "controlmm",
            "retarget",
            str(motion),
            "--out",
            str(tmp_path / "b"),
            "--render",
            str(tmp_path / "b.gif"),
            *small,
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert res.returncode == 0, res.stderr
    if "(mujoco)" in res.stdout:
        pytest.skip("this machine has OSMesa, so the fallback path is not exercised")
    assert "(stick)" in res.stdout
    notes = [
        line for line in res.stderr.splitlines() if "MuJoCo rendering unavailable (MUJOCO_GL=osmesa" in line
    ]
    assert len(notes) == 1 and "stick figure" in notes[0]
    assert (tmp_path / "b.gif").read_bytes()[:6] in (b"GIF89a", b"GIF87a")
