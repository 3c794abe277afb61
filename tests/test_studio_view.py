"""What the studio's viewer draws, without a model: MuJoCo geoms as meshes, body poses and contacts."""

from __future__ import annotations

import base64

import mujoco
import numpy as np
import pytest
from cli_helpers import one_line_error

from controlmm.studio.geometry import box, capsule, cylinder, ellipsoid
from controlmm.studio.run import plan_dirs
from controlmm.studio.view import PLAN_FILES, body_poses_and_contacts, moving_bodies, scene_geometry
from scenes import load_scene


def _edges_twice(faces: np.ndarray) -> bool:
    """A closed surface: every undirected edge is shared by exactly two triangles."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool((counts == 2).all())


@pytest.mark.parametrize(
    ("mesh", "extent"),
    [
        (box(np.array([0.1, 0.2, 0.3])), [0.1, 0.2, 0.3]),
        (capsule(0.05, 0.2), [0.05, 0.05, 0.25]),
        (cylinder(0.1, 0.4), [0.1, 0.1, 0.4]),
        (ellipsoid(np.array([0.3, 0.2, 0.1])), [0.3, 0.2, 0.1]),
    ],
)
def test_primitives_are_closed_and_sized(mesh, extent):
    verts, faces = mesh
    assert verts.dtype == np.float32 and faces.max() < len(verts)
    assert np.abs(verts).max(axis=0) == pytest.approx(extent, rel=1e-5)
    assert _edges_twice(faces)


@pytest.fixture(scope="module")
def table():
    return load_scene("table", robot="g1")


def test_scene_geometry_draws_the_robot_and_the_table_where_mujoco_has_them(table):
    doc = scene_geometry(table)
    robot = [g for g in doc["geoms"] if g["kind"] == "robot"]
    assert len(robot) > 20 and all(g["body"] >= 0 for g in robot)  # riding on moving bodies
    (top,) = [g for g in doc["geoms"] if g["name"] == "table_top"]
    gid = table.model.geom("table_top").id
    data = mujoco.MjData(table.model)
    mujoco.mj_kinematics(table.model, data)
    assert top["body"] == -1 and top["pos"] == pytest.approx(data.geom_xpos[gid].tolist())
    assert doc["bodies"] == [table.model.body(b).name for b in moving_bodies(table)]
    for key in {g["mesh"] for g in doc["geoms"]}:
        m = doc["meshes"][key]
        verts = np.frombuffer(base64.b64decode(m["vertices"]), "<f4").reshape(-1, 3)
        faces = np.frombuffer(base64.b64decode(m["faces"]), "<u2" if m["index"] == "u2" else "<u4")
        assert len(faces) % 3 == 0 and faces.max() < len(verts)


def test_poses_follow_the_qpos_and_contacts_show_a_hand_in_the_table(table):
    start = table.robot_start_qpos()
    inside = start.copy()
    top = table.model.geom("table_top").id
    data = mujoco.MjData(table.model)
    mujoco.mj_kinematics(table.model, data)
    inside[0:2] = data.geom_xpos[top][:2]  # the robot standing in the middle of the table top
    qpos = np.stack([start, inside])
    poses, contacts = body_poses_and_contacts(table, qpos, fps=50.0)
    assert poses.shape == (2, len(moving_bodies(table)), 7)
    assert poses[1, 0, :2] == pytest.approx(inside[0:2], abs=1e-6)  # the floating base
    assert not [c for c in contacts if c[0] == 0]  # standing at the start: nothing penetrates
    hits = [c for c in contacts if c[0] == 1]
    assert hits and all(c[4] > 0 for c in hits)
    assert {c[5] for c in hits} <= {table.model.body(b).name for b in moving_bodies(table)}
    with pytest.raises(Exception, match="qpos columns"):
        body_poses_and_contacts(table, qpos[:, :10], fps=50.0)


def test_view_and_studio_refuse_bad_input_with_one_line(capsys, tmp_path):
    one_line_error(capsys, ["view", str(tmp_path)], "is not a plan output")
    one_line_error(capsys, ["view", str(tmp_path / "missing")], "is not a directory")
    one_line_error(capsys, ["studio", "--model", str(tmp_path / "missing")], "does not exist")
    one_line_error(capsys, ["studio", "--port", "70000"], "--port", "70000")


def test_view_finds_one_plan_or_a_folder_of_plans(tmp_path):
    for name in ("seed0", "seed1"):
        for f in PLAN_FILES:
            (tmp_path / "batch" / name).mkdir(parents=True, exist_ok=True)
            (tmp_path / "batch" / name / f).write_text("{}")
    (tmp_path / "batch" / "notes").mkdir()
    assert [p.name for p in plan_dirs(tmp_path / "batch")] == ["seed0", "seed1"]
    assert plan_dirs(tmp_path / "batch" / "seed1") == [tmp_path / "batch" / "seed1"]
