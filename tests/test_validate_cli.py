"""`controlmm validate` on trajectories from this project and in the Unitree CSV layout."""

import json

import mujoco
import numpy as np
import pytest

from controlmm.cli.main import main
from retarget import robot_mjcf
from sim.files import load_qpos


@pytest.fixture(scope="module")
def stand_qpos():
    model = mujoco.MjModel.from_xml_path(str(robot_mjcf("g1")))
    key = model.key("stand").qpos.copy()
    return np.repeat(key[None], 40, axis=0)


def _write_ours(path, qpos, fps=50.0, robot="g1"):
    np.savez(path, qpos=qpos, fps=np.float64(fps), robot=np.array(robot))


def test_standing_robot_passes_and_csv_matches_npz(tmp_path, stand_qpos, capsys):
    _write_ours(tmp_path / "stand.npz", stand_qpos)
    rows = np.concatenate([stand_qpos[:, :3], stand_qpos[:, [4, 5, 6, 3]], stand_qpos[:, 7:]], axis=1)
    np.savetxt(tmp_path / "stand.csv", rows, delimiter=",")
    q_npz, fps, robot = load_qpos(tmp_path / "stand.npz")
    q_csv, _, _ = load_qpos(tmp_path / "stand.csv", fps=50)
    assert robot == "g1" and fps == 50.0 and np.allclose(q_npz, q_csv)
    assert main(["validate", str(tmp_path / "stand.npz"), "--out", str(tmp_path / "report.json")]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["passed"] is True
    assert (tmp_path / "report.png").stat().st_size > 1000
    assert "PASSED" in capsys.readouterr().out


def test_robot_pushed_into_an_obstacle_fails(tmp_path, stand_qpos):
    sunk = stand_qpos.copy()
    sunk[:, 2] -= 0.1  # 10 cm into the floor
    _write_ours(tmp_path / "sunk.npz", sunk)
    assert main(["validate", str(tmp_path / "sunk.npz"), "--out", str(tmp_path / "r.json"), "--no-plot"]) == 1
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["passed"] is False and report["floor_penetration_m"] > 0.05


@pytest.mark.parametrize(
    "args,needle",
    [
        (["missing.npz"], "does not exist"),
        (["traj.txt"], "allowed: .npz, .csv"),
        (["stand.csv"], "--fps"),
        (["stand.npz", "--robot", "h1"], "does not match"),
        (["stand.npz", "--scene", "nowhere"], "unknown scene"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, stand_qpos, capsys, args, needle):
    _write_ours(tmp_path / "stand.npz", stand_qpos)
    np.savetxt(tmp_path / "stand.csv", np.zeros((3, 36)), delimiter=",")
    (tmp_path / "traj.txt").write_text("x")
    argv = ["validate", str(tmp_path / args[0]), *args[1:], "--out", str(tmp_path / "r.json")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not (tmp_path / "r.json").exists()
