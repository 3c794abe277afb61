"""Tracker formats out (LAFAN1-G1 CSV, MuJoCo-qpos CSV, BeyondMimic NPZ, GMR pickle): write, read back
with plain readers and with ours, same qpos; `validate` and `retarget --format` on them."""

import json
import os
import pickle

import mujoco
import numpy as np
import pytest
from cli_helpers import one_line_error, run_cli
from scipy.spatial.transform import Rotation

from controlmm.errors import InputFileError
from controlmm.files import load_pickle
from controlmm.motion import Motion
from retarget import read_export, retarget_motion, save_trajectory
from retarget.exports import BEYONDMIMIC_FPS, parse_formats, world_angular_velocity


@pytest.fixture(scope="module")
def traj(sample_joints):
    """2 s of the real sample retargeted to the G1 at 30 fps."""
    return retarget_motion(Motion(sample_joints[:41]), robot="g1", fps=30)


@pytest.fixture(scope="module")
def files(traj, tmp_path_factory):
    folder = tmp_path_factory.mktemp("exports")
    return save_trajectory(traj, folder / "walk", parse_formats("all"))


def test_files_and_names(files):
    assert sorted(p.name for p in files.values()) == [
        "walk.csv",
        "walk.json",
        "walk.npz",
        "walk.pkl",
        "walk_beyondmimic.npz",
        "walk_qpos.csv",
    ]


def test_csvs_with_a_plain_reader(traj, files):
    lafan = np.loadtxt(files["lafan1"], delimiter=",")
    qpos = np.loadtxt(files["qpos"], delimiter=",")
    assert lafan.shape == qpos.shape == traj.qpos.shape
    assert np.array_equal(qpos, traj.qpos)  # wxyz, exactly (17 digits)
    assert np.array_equal(lafan[:, 3:7], traj.qpos[:, [4, 5, 6, 3]])  # xyzw
    assert np.array_equal(lafan[:, [0, 1, 2]], qpos[:, :3]) and np.array_equal(lafan[:, 7:], qpos[:, 7:])
    for fmt in ("lafan1", "qpos"):
        back, fps = read_export(files[fmt], fps=30)
        assert fps == 30 and np.array_equal(back, traj.qpos)


def test_gmr_pickle_with_plain_pickle(traj, files):
    with open(files["gmr"], "rb") as fh:
        data = pickle.load(fh)  # what GMR's own loader does
    assert data["fps"] == 30.0 and data["link_body_list"][0] == "pelvis"
    assert np.array_equal(data["root_rot"], traj.qpos[:, [4, 5, 6, 3]])  # xyzw
    assert np.array_equal(data["dof_pos"], traj.qpos[:, 7:]) and np.array_equal(
        data["root_pos"], traj.qpos[:, :3]
    )
    assert data["local_body_pos"].shape == (traj.num_frames, len(data["link_body_list"]), 3)
    assert np.allclose(data["local_body_pos"][:, 0], 0.0)  # the root at the origin
    back, fps = read_export(files["gmr"])
    assert fps == 30.0 and np.array_equal(back, traj.qpos)


def test_beyondmimic_npz_at_50_fps(traj, files):
    data = np.load(files["beyondmimic"])
    assert data["fps"].tolist() == [BEYONDMIMIC_FPS]
    t = data["joint_pos"].shape[0]
    assert t == int((traj.num_frames - 1) / 30 * 50) + 1
    b = len(data["body_names"])
    assert (
        data["body_pos_w"].shape == data["body_lin_vel_w"].shape == data["body_ang_vel_w"].shape == (t, b, 3)
    )
    assert data["body_quat_w"].shape == (t, b, 4) and data["joint_vel"].shape == data["joint_pos"].shape
    # The root body's pose and the joints are the trajectory's at the shared instants (0, 0.1 s, ...).
    back, fps = read_export(files["beyondmimic"])
    assert fps == 50 and np.allclose(back[::5], traj.qpos[::3], atol=2e-6)
    # Velocities agree with positions: the integrated joint velocity and body speed.
    dt = 1 / 50
    assert np.allclose(
        data["joint_vel"][1:-1], (data["joint_pos"][2:] - data["joint_pos"][:-2]) / (2 * dt), atol=1e-3
    )
    assert np.abs(data["body_lin_vel_w"][:, 0, 0].mean() - (back[-1, 0] - back[0, 0]) / ((t - 1) * dt)) < 0.05


def test_world_angular_velocity_of_a_steady_spin():
    times = np.arange(20) / 50
    rot = Rotation.from_rotvec(np.outer(times, [0.0, 0.0, 2.0]))  # 2 rad/s about world z
    base = Rotation.from_euler("x", 0.7)  # a tilted body: world-frame rates stay [0, 0, 2]
    quat = (rot * base).as_quat()[:, [3, 0, 1, 2]][:, None]
    omega = world_angular_velocity(quat, 1 / 50)
    assert np.allclose(omega[:, 0], [0.0, 0.0, 2.0], atol=1e-9)


def test_validate_reads_each_export(files, capsys, tmp_path):
    verdicts = []
    for path, extra, fps in (
        (files["gmr"], [], 30),
        (files["beyondmimic"], [], 50),
        (files["qpos"], ["--fps", "30", "--quat-order", "wxyz"], 30),
        (files["lafan1"], ["--fps", "30"], 30),
    ):
        report_path = tmp_path / f"{path.name}.json"
        code = run_cli(["validate", str(path), "--out", str(report_path), "--no-plot", *extra])
        report = json.loads(report_path.read_text())
        assert report["fps"] == fps and report["num_frames"] == int(2 * fps) + 1
        verdicts.append((code, report["passed"], report["error_count"]))
    assert len(set(verdicts)) == 1  # the same trajectory, the same verdict in every format
    # A wxyz file read as xyzw would tip the robot over: the order matters and is the user's to give.
    q_ok = read_export(files["qpos"], fps=30)[0]
    q_bad = read_export(files["qpos"], "lafan1", fps=30)[0]
    assert not np.allclose(q_ok, q_bad)


def test_pickles_that_run_code_are_refused(tmp_path, capsys):
    class Payload:
        def __reduce__(self):
            return (os.system, ("echo never",))

    path = tmp_path / "evil.pkl"
    path.write_bytes(pickle.dumps({"fps": 30.0, "root_pos": Payload()}))
    with pytest.raises(InputFileError, match="posix.system|nt.system"):
        load_pickle(path)
    one_line_error(
        capsys, ["validate", str(path), "--out", str(tmp_path / "r.json")], "refused", "not plain data"
    )
    assert not (tmp_path / "r.json").exists()


def test_retarget_format_option(tmp_path, sample_joints, capsys):
    src = tmp_path / "walk.npy"
    np.save(src, sample_joints[:41])
    out = tmp_path / "g1"
    assert run_cli(["retarget", str(src), "--out", str(out), "--format", "gmr,qpos"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "g1.json",
        "g1.npz",
        "g1.pkl",
        "g1_qpos.csv",
        "walk.npy",
    ]
    one_line_error(
        capsys, ["retarget", str(src), "--out", str(out), "--format", "bvh"], "unknown export format"
    )
    model = mujoco.MjModel.from_xml_path(json.loads((tmp_path / "g1.json").read_text())["mjcf"])
    assert np.loadtxt(tmp_path / "g1_qpos.csv", delimiter=",").shape[1] == model.nq
