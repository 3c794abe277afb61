"""Report JSON, atomic writing, summary, plot, bad input and scene-like inputs."""

from __future__ import annotations

import json
import os
from types import SimpleNamespace

import numpy as np
import pytest
from sim_motions import FPS, g1_stand, g1_world, hold, smooth_blend

from controlmm.errors import ControlMMError
from sim import CheckConfig, Failure, check_pose, check_trajectory, load_report, make_world, plot_report
from sim.failures import from_events, runs


@pytest.fixture(scope="module")
def failing_report():
    """G1 sinks 3 cm into the floor (frames ~12-27) and overshoots its elbow limit."""
    w = g1_world()
    q0 = g1_stand()
    bad = q0.copy()
    bad[2] -= 0.03
    bad[w.model.jnt_qposadr[w.model.joint("left_elbow_joint").id]] = 2.2
    q = np.concatenate(
        [hold(q0, 10), smooth_blend(q0, bad, 5), hold(bad, 10), smooth_blend(bad, q0, 5), hold(q0, 5)]
    )
    return check_trajectory(w, q, FPS)


def test_report_json_fields(failing_report, tmp_path):
    r = failing_report
    data = json.loads(r.to_json())
    for key in (
        "passed",
        "max_penetration_m",
        "floor_penetration_m",
        "self_collision_frames",
        "joint_limit_violations",
        "foot_sliding_m",
        "residual_force",
        "failures",
        "frames",
    ):
        assert key in data
    assert data["passed"] is False and data["format"] == "controlmm.sim.report/1"
    assert set(data["residual_force"]) == {
        "mean_ratio",
        "p95_ratio",
        "max_ratio",
        "max_N",
        "sustained_max_ratio",
    }
    assert data["error_count"] >= 2 and set(data["error_kinds"]) >= {"floor_penetration", "joint_limit"}
    assert data["floor_penetration_m"] == pytest.approx(0.03186, abs=3e-4)
    assert data["joint_limit_violations"] > 0
    kinds = {f["kind"] for f in data["failures"]}
    assert {"floor_penetration", "joint_limit"} <= kinds
    for f in data["failures"]:
        assert set(f) == {
            "kind",
            "frame_start",
            "frame_end",
            "robot_body",
            "obstacle_geom",
            "depth",
            "joint",
            "severity",
        }
        assert f["severity"] in ("error", "warning")
        assert 0 <= f["frame_start"] <= f["frame_end"] < r.num_frames
    frames = data["frames"]
    assert all(len(v) == r.num_frames for v in frames.values())
    assert frames["clearance_m"][0] is None  # no obstacle within sensing distance: not measured
    assert "foot_height_m:left_ankle_roll_link" in frames
    assert data["config"]["floor_penetration_m"] == 0.005
    path = tmp_path / "report.json"
    r.save(path)
    assert json.loads(path.read_text())["failures"] == data["failures"]
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]  # no temporary file left
    back = load_report(path)
    assert back.passed is False and len(back.failures) == len(r.failures)
    for a, b in zip(back.failures, r.failures, strict=True):
        assert (a.kind, a.frame_start, a.frame_end, a.robot_body, a.obstacle_geom, a.joint, a.severity) == (
            b.kind,
            b.frame_start,
            b.frame_end,
            b.robot_body,
            b.obstacle_geom,
            b.joint,
            b.severity,
        )
        assert a.depth == pytest.approx(b.depth, abs=1e-6)
    assert back.floor_penetration_m == pytest.approx(r.floor_penetration_m, abs=1e-6)
    np.testing.assert_allclose(back.frames["floor_penetration_m"], r.frames["floor_penetration_m"], atol=1e-6)


def test_save_is_atomic(failing_report, tmp_path):
    (tmp_path / "a_file").write_text("mine")
    with pytest.raises(ControlMMError, match="is not a directory"):
        failing_report.save(tmp_path / "a_file" / "report.json")
    assert [p.name for p in tmp_path.iterdir()] == ["a_file"]
    (tmp_path / "a_file").unlink()
    target = tmp_path / "report.json"
    target.write_text("previous")
    failing_report.save(target)  # replaces the old file in one rename
    assert json.loads(target.read_text())["passed"] is False
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.json"]
    readonly = tmp_path / "readonly"
    readonly.mkdir()
    readonly.chmod(0o500)
    try:
        if not os.access(readonly, os.W_OK):  # (root ignores permissions)
            with pytest.raises(ControlMMError, match="not writable"):
                failing_report.save(readonly / "report.json")
            assert list(readonly.iterdir()) == []
    finally:
        readonly.chmod(0o700)
    target.write_text('{"a": 1}')
    with pytest.raises(ControlMMError, match="not a controlmm simulation report"):
        load_report(target)


def test_summary_is_short_and_names_failures(failing_report):
    text = failing_report.summary()
    lines = text.splitlines()
    assert lines[0].startswith("FAILED: 35 frames at 50 fps")
    assert len(lines) <= 5 + 8 + 1
    assert any("floor_penetration left_ankle_roll_link x floor" in line for line in lines)
    assert any("joint_limit left_elbow_joint" in line for line in lines)
    passed = check_trajectory(g1_world(), hold(g1_stand(), 5), FPS)
    assert passed.summary().startswith("PASSED: 5 frames") and len(passed.summary().splitlines()) == 4


def test_plot_png(failing_report, tmp_path):
    from PIL import Image

    path = tmp_path / "check.png"
    plot_report(failing_report, path)
    assert path.stat().st_size > 20_000
    with Image.open(path) as im:
        assert im.size[0] > 800 and im.size[1] > 800
        pixels = np.asarray(im.convert("L"))
    assert pixels.std() > 10  # drawn, not blank
    plot_report(load_report_roundtrip(failing_report, tmp_path), tmp_path / "again.png")
    assert (tmp_path / "again.png").stat().st_size > 20_000


def load_report_roundtrip(report, tmp_path):
    report.save(tmp_path / "r.json")
    return load_report(tmp_path / "r.json")


def test_bad_input_one_line_errors():
    w = g1_world()
    q = hold(g1_stand(), 4)
    cases = [
        (q[:, :35], "qpos has shape (4, 35); the model expects (T, nq=36"),
        (np.where(np.arange(36) == 9, np.nan, q), "NaN/inf (first at frame 0, column 9)"),
        (np.zeros((0, 36)), "no frames"),
        (np.zeros((2, 36)), "zero root quaternion"),
        ("walk", "numeric"),
    ]
    for bad, message in cases:
        with pytest.raises(ControlMMError) as err:
            check_trajectory(w, bad, FPS)
        assert message in str(err.value) and "\n" not in str(err.value)
    for fps in (0, -5, 5000, float("nan"), "fast", None):
        with pytest.raises(ControlMMError, match=r"fps must be a number in \[1, 1000\]"):
            check_trajectory(w, q, fps)
    config = CheckConfig(velocity_limits={"left_knee_joint": 5.0})
    assert (
        config.velocity_limit("left_knee_joint") == 5.0 and config.velocity_limit("right_knee_joint") == 20.0
    )
    assert config.velocity_limit("robot/left_ankle") == 9.0  # H1, attached with a prefix
    assert config.velocity_limit("tail") == pytest.approx(3 * np.pi)
    with pytest.raises(ControlMMError, match="CheckConfig.floor_penetration_m"):
        CheckConfig(floor_penetration_m=-1)
    with pytest.raises(ControlMMError, match="self_collision"):
        CheckConfig(self_collision="meshes")
    with pytest.raises(ControlMMError, match="expected a mujoco.MjModel"):
        check_trajectory("scene.xml", q, FPS)
    with pytest.raises(ControlMMError, match="foot body 'toe'"):
        check_trajectory(w.model, q, FPS, foot_bodies=["toe"])


def test_scene_like_objects_and_trajectory_objects():
    w = g1_world()
    m = w.model
    shelf = m.geom("shelf").id
    # a Scene-shaped object: explicit sets, the shelf deliberately left out of the obstacles
    scene = SimpleNamespace(
        model=m,
        robot_geom_ids=w.robot_geoms.tolist(),
        floor_geom_ids=[m.geom("floor").id],
        obstacle_geom_ids=[m.geom("post").id],
        set_time=None,
    )
    world = make_world(scene)
    assert world.obstacle_geoms.tolist() == [m.geom("post").id] and shelf not in world.obstacle_geoms
    traj = SimpleNamespace(qpos=hold(g1_stand(), 6), fps=30.0)
    report = check_trajectory(scene, traj)
    assert report.passed and report.fps == 30.0 and report.extra["obstacles"] == ["post"]
    assert check_pose(world, g1_stand()).passed
    with pytest.raises(ControlMMError, match="both robot and floor/obstacle"):
        make_world(
            SimpleNamespace(
                model=m, robot_geom_ids=[shelf] + w.robot_geoms.tolist(), obstacle_geom_ids=[shelf]
            )
        )


def test_failure_merging():
    assert runs(np.array([0, 1, 1, 0, 1, 0, 0, 1, 1], dtype=bool)) == [(1, 2), (4, 4), (7, 8)]
    frames = np.array([3, 4, 5, 9, 4, 5])
    keys = np.array([7] * 4 + [2] * 2)
    depths = np.array([0.1, 0.3, 0.2, 0.5, 0.05, 0.06])
    names = {7: ("a", 1), 2: ("b", 2)}
    out = from_events("obstacle_penetration", frames, keys, depths, names.__getitem__)
    kind = "obstacle_penetration"
    assert out == [
        Failure(kind, 4, 5, "b", 2, 0.06),
        Failure(kind, 3, 5, "a", 1, 0.3),
        Failure(kind, 9, 9, "a", 1, 0.5),
    ]
    assert "frames 3-5 (0.06-0.10 s)" in out[1].describe(fps=50.0)
