"""The scene library: every scene compiles with and without robots, metadata, bad input."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh
from scene_helpers import user_scene_xml

from controlmm.errors import ControlMMError
from controlmm.motion.skeleton import JOINT_NAMES
from retarget.robots import robot_mjcf
from scenes import list_scenes, load_scene

EXPECTED = {
    "empty",
    "corridor",
    "pillars",
    "table",
    "low_beam",
    "doorway",
    "moving_obstacle",
    "mesh_rock",
    "room",
}


@pytest.fixture(scope="module")
def robot_models():
    return {name: mujoco.MjModel.from_xml_path(str(robot_mjcf(name))) for name in ("g1", "h1")}


def test_library_has_the_required_scenes():
    assert EXPECTED <= set(list_scenes())
    assert len(list_scenes()) >= 8


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_scene_compiles_alone_and_with_robots(name, robot_models):
    alone = load_scene(name, robot=None)
    assert alone.model.nq == 0 and alone.robot_geom_ids == ()
    assert len(alone.floor_geom_ids) == 1 and alone.floor_height == 0.0
    assert (len(alone.obstacle_geom_ids) > 0) == (name != "empty")
    for robot, ref in robot_models.items():
        scene = load_scene(name, robot=robot)
        m = scene.model
        assert m.nq == ref.nq and m.nv == ref.nv and m.nu == ref.nu
        assert [m.joint(i).name for i in range(m.njnt)] == [ref.joint(i).name for i in range(ref.njnt)]
        assert {m.body(i).name for i in range(m.nbody)} >= {ref.body(i).name for i in range(1, ref.nbody)}
        assert len(scene.robot_geom_ids) == ref.ngeom
        assert scene.obstacle_geom_ids == alone.obstacle_geom_ids  # the robot comes after the scene
        assert set(scene.robot_geom_ids).isdisjoint(scene.obstacle_geom_ids + scene.floor_geom_ids)
        assert m.opt.timestep == ref.opt.timestep and m.opt.integrator == ref.opt.integrator
        qpos = scene.robot_start_qpos()
        assert qpos.shape == (ref.nq,) and np.allclose(qpos[:2], scene.start[:2])


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_scene_metadata(name):
    scene = load_scene(name, robot=None)
    assert len(scene.description) > 40 and len(scene.suggested_prompt) > 10
    control = scene.suggested_control
    assert control["coords"] == "world" and control["constraints"]
    for c in control["constraints"]:
        assert c["joint"] in JOINT_NAMES and 0 <= c["frame"] < 196 and len(c["position"]) == 3
    assert len(scene.start) == 3 and all(np.isfinite(scene.start))


def _robot_contacts(scene, qpos) -> list[str]:
    """Names of obstacle geoms touching the robot in pose ``qpos``."""
    m = scene.model
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    robot, obstacles = set(scene.robot_geom_ids), set(scene.obstacle_geom_ids)
    hits = set()
    for c in d.contact[: d.ncon]:
        g1, g2 = int(c.geom1), int(c.geom2)
        if (g1 in robot and g2 in obstacles) or (g2 in robot and g1 in obstacles):
            hits.add(m.geom(g2 if g2 in obstacles else g1).name)
    return sorted(hits)


def test_g1_feasibility_of_the_obstacle_sizes():
    """Standing G1 hits the low beam but fits the doorway and the corridor gaps."""
    beam = load_scene("low_beam", robot="g1")
    qpos = beam.robot_start_qpos()
    qpos[0] = 2.5
    assert "beam" in _robot_contacts(beam, qpos)
    door = load_scene("doorway", robot="g1")
    qpos = door.robot_start_qpos()
    qpos[:2] = (2.5, 0.0)
    assert _robot_contacts(door, qpos) == []
    qpos[1] = 0.5  # straight ahead of the start: the wall
    assert _robot_contacts(door, qpos)
    corridor = load_scene("corridor", robot="g1")
    qpos = corridor.robot_start_qpos()
    for x, y in [(2.0, -0.4), (4.0, 0.4)]:
        qpos[:2] = (x, y)
        assert _robot_contacts(corridor, qpos) == []
    qpos[:2] = (2.0, 0.0)
    assert "box_left" in _robot_contacts(corridor, qpos)


def test_moving_obstacle_follows_its_track():
    scene = load_scene("moving_obstacle", robot="g1")
    m = scene.model
    d = mujoco.MjData(m)
    cart = m.body("cart").id
    track = scene.tracks["cart"]
    for t, y in [(0.0, -2.5), (1.25, -1.25), (2.5, 0.0), (5.0, 2.5), (9.0, 2.5)]:
        scene.set_time(d, t)
        mujoco.mj_kinematics(m, d)
        assert np.allclose(d.xpos[cart], [2.2, y, 0.5], atol=1e-9)
    scene.set_time(d, 2.5)
    mujoco.mj_kinematics(m, d)
    yaw = np.arctan2(d.xmat[cart][3], d.xmat[cart][0])
    assert yaw == pytest.approx(np.pi / 4, abs=1e-6)
    assert track.duration == 5.0 and scene.moving_geom_ids == (m.geom("cart").id,)


def test_user_mjcf_loads_like_a_packaged_scene(tmp_path):
    trimesh.creation.box(extents=(0.4, 0.3, 0.6)).export(tmp_path / "block.stl")
    path = tmp_path / "mine.xml"
    path.write_text(user_scene_xml("block.stl"))
    scene = load_scene(str(path), robot="g1")
    assert scene.name == "mine" and scene.model.nq == 36
    assert scene.description == "my test scene" and scene.suggested_control["constraints"][0]["frame"] == 10
    assert scene.start == (0.5, -0.5, pytest.approx(1.5707963))
    names = {scene.geom_name(g) for g in scene.obstacle_geom_ids}
    assert names == {"block", "post", "ball"}  # visual-only 'decor' and the floor are not obstacles
    assert [scene.geom_name(g) for g in scene.floor_geom_ids] == ["ground"]
    assert "ball" in scene.tracks
    tf = scene.human_to_world(0.8)
    assert tf.scale == 0.8 and tf.translation == (0.5, -0.5, 0.0)


def _error(fn) -> str:
    with pytest.raises(ControlMMError) as info:
        fn()
    message = str(info.value)
    assert "\n" not in message
    return message


def test_bad_input_messages(tmp_path):
    msg = _error(lambda: load_scene("no_such_scene"))
    assert "unknown scene 'no_such_scene'" in msg and "low_beam" in msg and "corridor" in msg
    assert "does not exist" in _error(lambda: load_scene(str(tmp_path / "missing.xml")))
    bad = tmp_path / "bad.xml"
    bad.write_text('<mujoco>\n<worldbody>\n<geom type="boxx" size="1 1 1"/>\n</worldbody>\n</mujoco>\n')
    msg = _error(lambda: load_scene(str(bad)))
    assert "bad.xml" in msg and "line 3" in msg and "boxx" in msg
    bad.write_text('<mujoco>\n<worldbody>\n<geom type="box" size="1 1 1">\n</worldbody></mujoco>\n')
    msg = _error(lambda: load_scene(str(bad)))
    assert "bad.xml" in msg and "Line number=3" in msg
    jointed = tmp_path / "jointed.xml"
    jointed.write_text(
        '<mujoco><worldbody><body name="door"><joint name="hinge"/>'
        '<geom type="box" size=".1 .1 .1"/></body></worldbody></mujoco>'
    )
    assert "has joints (hinge)" in _error(lambda: load_scene(str(jointed), robot=None))
    track = tmp_path / "track.xml"
    track.write_text(
        '<mujoco><custom><numeric name="controlmm.track.m" data="1 0 0 0 1 0 0 0 0.5 0 0 0 1 0 0 0"/>'
        '</custom><worldbody><body name="m" mocap="true"><geom size=".1"/></body></worldbody></mujoco>'
    )
    assert "strictly increasing times" in _error(lambda: load_scene(str(track), robot=None))
    assert "unknown robot 'r2d2'" in _error(lambda: load_scene("empty", robot="r2d2"))
    # a robot file that does not compile, its keyframe longer than its joints (Menagerie's
    # Shadow hand scene with its forearm commented out, as humanoid-bench ships it): one line,
    # not MuJoCo's error from placing the robot in the scene
    keyed = tmp_path / "keyed.xml"
    qpos = " ".join(["0"] * 31)
    keyed.write_text(
        f'<mujoco><worldbody><body name="ball"><freejoint/><geom size=".1"/></body></worldbody>'
        f'<keyframe><key qpos="{qpos}"/></keyframe></mujoco>'
    )
    msg = _error(lambda: load_scene("empty", robot=str(keyed)))
    assert "keyed.xml' does not compile" in msg and "qpos size" in msg, msg
    # a robot whose mesh file is missing: the robot's file is named, not the scene's
    g1 = robot_mjcf("g1")
    meshless = tmp_path / "meshless.xml"
    text = g1.read_text().replace('meshdir="assets"', f'meshdir="{g1.parent / "assets"}"')
    meshless.write_text(
        text.replace('<mesh file="pelvis.STL"/>', '<mesh name="pelvis" file="no_such_pelvis.STL"/>')
    )
    msg = _error(lambda: load_scene("empty", robot=str(meshless)))
    assert "meshless.xml' does not compile" in msg and "no_such_pelvis.STL" in msg, msg
    assert "empty.xml" not in msg, msg
