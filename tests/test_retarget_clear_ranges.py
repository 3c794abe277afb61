"""Trunk joints kept where the robot's own trunk geoms leave them clear (retarget.clear_ranges),
and the solver's start: elbow joints resting at a limit start inside their range
(retarget.reference.start_q)."""

from __future__ import annotations

import itertools
import json

import mujoco
import numpy as np
import pytest
from capsule_humanoid import capsule_humanoid_xml
from robot_checks import independent_check

from controlmm.frames import HumanToWorld
from controlmm.motion.skeleton import JOINT_INDEX
from retarget import infer_mapping, load_robot, retarget_motion
from retarget.clear_ranges import CLEAR_DEPTH
from retarget.compare import resample_human, robot_keypoints, umeyama
from retarget.reference import INSIDE_RANGE, elbow_joints, start_q


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


def test_a_straight_elbow_at_its_limit_starts_bent(tmp_path):
    path = tmp_path / "plain.xml"
    path.write_text(capsule_humanoid_xml("plain"))
    caps = load_robot(str(path))
    q = start_q(caps)
    moved = np.flatnonzero(q != caps.rest_q)
    names = {caps.tree.joint_names[j] for j in moved}
    assert names == {"elbow_l", "elbow_r"}  # range (-150, 0) degrees, rest 0
    assert set(moved) <= set(elbow_joints(caps))
    np.testing.assert_allclose(q[moved], caps.upper[moved] - INSIDE_RANGE * (caps.upper - caps.lower)[moved])
    g1 = load_robot("g1")  # every joint inside its range at rest: the rest pose itself
    np.testing.assert_array_equal(start_q(g1), g1.rest_q)


def test_an_arm_raised_over_the_head_is_followed_with_an_elbow_resting_at_its_limit(tmp_path, sample_joints):
    """The capsule humanoid's elbows rest straight at the end of their range; started there, the
    solver left the right arm hanging while the human's rose over the head (frames 35-42 at
    30 fps: the wrist 23 cm from the human's after the similarity alignment)."""
    path = tmp_path / "plain.xml"
    path.write_text(capsule_humanoid_xml("plain"))
    robot = load_robot(str(path))
    qpos = retarget_motion(sample_joints, str(path), fps=30.0).qpos
    names = ("left_elbow", "right_elbow", "left_wrist", "right_wrist", "pelvis", "left_knee", "right_knee")
    kp = robot_keypoints(robot, qpos)[:, [robot.keypoint_index(n) for n in names]]
    human = HumanToWorld(scale=1.0).to_world(resample_human(sample_joints, 20.0, len(qpos), 30.0))
    ref = np.asarray(human)[:, [JOINT_INDEX[n] for n in names]]
    s, rot, t = umeyama(ref.reshape(-1, 3), kp.reshape(-1, 3))
    err = np.linalg.norm(s * ref @ rot.T + t - kp, axis=-1)
    assert err[:, 3].max() < 0.2
