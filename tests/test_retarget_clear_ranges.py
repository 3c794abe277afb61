"""Trunk joints, knees and elbows kept where the robot's own geoms leave them clear
(retarget.clear_ranges)."""

from __future__ import annotations

import itertools
import json

import mujoco
import numpy as np
import pytest
from capsule_humanoid import capsule_humanoid_xml
from robot_checks import independent_check

from retarget import infer_mapping, retarget_motion
from retarget.clear_ranges import CLEAR_DEPTH
from retarget.robot_files import ancestors


def _box_trunk_xml() -> str:
    """The plain capsule humanoid with its pelvis and chest written as boxes 1 cm apart at rest:
    rolling or pitching the two-link spine brings the chest's box into the pelvis's."""
    xml = capsule_humanoid_xml("plain")
    pelvis = '<geom type="capsule" fromto="0 -0.09 0 0 0.09 0" size="0.08"/>'
    chest = '<geom type="capsule" fromto="0 -0.09 0.1 0 0.09 0.1" size="0.08"/>'
    assert pelvis in xml and chest in xml
    return xml.replace(pelvis, '<geom type="box" size="0.1 0.12 0.1"/>', 1).replace(
        chest, '<geom type="box" size="0.1 0.12 0.14"/>', 1
    )


def _pelvis_chest_overlap(model: mujoco.MjModel, qpos: np.ndarray) -> float:
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    pair = {model.body("root").id, model.body("chest").id}
    deep = [
        -c.dist
        for c in data.contact[: data.ncon]
        if {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])} == pair
    ]
    return max(deep, default=0.0)


def test_waist_joints_are_kept_where_the_trunk_geoms_leave_them_clear(tmp_path, sample_joints):
    path = tmp_path / "box_trunk.xml"
    path.write_text(_box_trunk_xml())
    mapping = infer_mapping(path)
    ranges = mapping["ranges"]
    assert set(ranges) == {"spine_x", "spine_y", "chest_x", "chest_y"}  # chest_z turns it in place
    model = mujoco.MjModel.from_xml_path(str(path))
    adr = [int(model.joint(n).qposadr[0]) for n in ranges]
    # Every combination of the kept ranges' ends is clear; the MJCF's own ends are not.
    for ends in itertools.product(*ranges.values()):
        q = model.qpos0.copy()
        q[adr] = ends
        assert _pelvis_chest_overlap(model, q) <= CLEAR_DEPTH
    for name in ranges:
        q = model.qpos0.copy()
        q[model.joint(name).qposadr[0]] = model.joint(name).range[1]
        assert _pelvis_chest_overlap(model, q) > 0.005
    # Retargeting the real clip: with the ranges the chest stays out of the pelvis, without
    # them (the same mapping, the MJCF's ranges) it does not.
    frames = {}
    for tag, data in (("ranges", mapping), ("mjcf", {k: v for k, v in mapping.items() if k != "ranges"})):
        file = tmp_path / f"{tag}.json"
        file.write_text(json.dumps(data))
        qpos = retarget_motion(sample_joints, str(file), fps=30.0).qpos
        frames[tag] = independent_check(path, qpos)[2]
    assert frames == {"ranges": 0, "mjcf": frames["mjcf"]} and frames["mjcf"] > 20


@pytest.mark.parametrize("robot", ["g1", "h1", "t1", "apollo"])
def test_a_trunk_clear_over_its_ranges_keeps_them(robot):
    assert "ranges" not in infer_mapping(robot)


def _wide_wrists_xml() -> str:
    """The plain capsule humanoid with wrists that turn +-170 degrees: the hand's sphere folds
    back into the forearm's capsule (an SMPL humanoid's wrists and hands turn +-180)."""
    xml = capsule_humanoid_xml("plain")
    for side in ("l", "r"):
        for axis, vec in (("x", "1 0 0"), ("y", "0 1 0")):
            old = f'<joint name="hand_{axis}_{side}" axis="{vec}" range="-60 60"/>'
            assert old in xml
            xml = xml.replace(old, old.replace('range="-60 60"', 'range="-170 170"'))
    return xml


def _hand_forearm_overlap(model: mujoco.MjModel, qpos: np.ndarray, side: str) -> float:
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    forearm = model.body(f"forearm_{side}").id
    hand = {b for b in range(model.nbody) if b != forearm and forearm in ancestors(model, b)}
    deep = [
        -c.dist
        for c in data.contact[: data.ncon]
        if {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])} & {forearm}
        and {int(model.geom_bodyid[c.geom1]), int(model.geom_bodyid[c.geom2])} & hand
    ]
    return max(deep, default=0.0)


def test_wrists_are_kept_where_the_hand_stays_out_of_the_forearm(tmp_path):
    path = tmp_path / "wide_wrists.xml"
    path.write_text(_wide_wrists_xml())
    ranges = infer_mapping(path)["ranges"]
    assert set(ranges) == {"hand_x_l", "hand_y_l", "hand_x_r", "hand_y_r"}
    model = mujoco.MjModel.from_xml_path(str(path))
    for side in ("l", "r"):
        names = [f"hand_x_{side}", f"hand_y_{side}"]
        adr = [int(model.joint(n).qposadr[0]) for n in names]
        for lo, hi in (ranges[n] for n in names):  # narrowed, still a wrist's range
            assert -np.pi < lo < -np.radians(60) and np.radians(60) < hi < np.pi
        for ends in itertools.product(*(ranges[n] for n in names)):
            q = model.qpos0.copy()
            q[adr] = ends
            assert _hand_forearm_overlap(model, q, side) <= CLEAR_DEPTH
        q = model.qpos0.copy()
        q[adr[0]] = np.radians(170)
        assert _hand_forearm_overlap(model, q, side) > 0.005
    # the plain humanoid's own wrists (+-60 degrees) and every packaged robot's are clear
    assert "ranges" not in infer_mapping(_write(tmp_path / "plain.xml", capsule_humanoid_xml("plain")))


def _write(path, text: str):
    path.write_text(text)
    return path
