"""Limbs written in ways seen outside the asset package, each the packaged G1 edited that way
(the same kinematics and geometry unless said): a shoulder hinge anchored far in along its own
axis (PAL's REEM-C puts its tilted shoulder joints on the torso's midline) and a leg that ends
at its knee in a point foot (ODRI's Bolt)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
from g1_variants import g1_spec, saved_without_controls

from retarget import infer_mapping, load_robot, robot_mjcf

SIDES = ("left", "right")


def _shoulders_anchored_in(tmp_path: Path, inward: float) -> Path:
    """The G1 with each shoulder pitch link's origin, and so its hinge's anchor, ``inward`` m
    along the hinge's axis towards the midline, everything on the link moved back by as much."""
    spec = g1_spec()
    for side, sign in (("left", 1.0), ("right", -1.0)):
        link = spec.body(f"{side}_shoulder_pitch_link")
        axis = np.asarray(link.joints[0].axis, dtype=float)
        shift = -sign * inward * axis / np.linalg.norm(axis)  # in the link's frame
        turn = np.zeros(9)
        mujoco.mju_quat2Mat(turn, np.asarray(link.quat, dtype=float))
        link.pos = np.asarray(link.pos) + turn.reshape(3, 3) @ shift
        for kind in (link.bodies, link.geoms, link.sites):
            for element in kind:
                element.pos = np.asarray(element.pos) - shift
        link.ipos = np.asarray(link.ipos) - shift
    return saved_without_controls(spec, tmp_path / "shoulders_in.xml")


def test_a_shoulder_anchored_on_the_midline_keeps_its_elbow(tmp_path):
    """Shoulder hinges anchored 10 cm in, on the G1's midline: the arm is measured from where
    the shoulder's first two axes cross, so its elbow is the elbow link and its wrist where the
    G1 file's is (measured from the midline, the shoulder roll link, a third of the way out,
    was taken for REEM-C's elbow)."""
    path = _shoulders_anchored_in(tmp_path, 0.10)
    robot = load_robot(path)
    left = robot.rest_keypoints[robot.keypoint_index("left_shoulder")]
    assert abs(robot.rest_keypoints[robot.keypoint_index("left_elbow"), 1] - left[1]) < 0.1
    mapping = infer_mapping(path)["keypoints"]
    plain_mapping = infer_mapping(robot_mjcf("g1"))["keypoints"]
    for side in SIDES:
        for joint in ("elbow", "wrist"):
            assert mapping[f"{side}_{joint}"]["body"] == plain_mapping[f"{side}_{joint}"]["body"], (
                side,
                joint,
            )
    plain = load_robot(robot_mjcf("g1"))
    for side in SIDES:
        for joint in ("elbow", "wrist"):
            k, p = robot.keypoint_index(f"{side}_{joint}"), plain.keypoint_index(f"{side}_{joint}")
            assert np.linalg.norm(robot.rest_keypoints[k] - plain.rest_keypoints[p]) < 0.01, (side, joint)


def _point_feet(tmp_path: Path) -> Path:
    """The G1 with its ankle joints removed: each foot welded to its shin, the leg ending at its
    knee (Bolt's point feet sit at the end of the shank)."""
    spec = g1_spec()
    for side in SIDES:
        for name in ("ankle_pitch", "ankle_roll"):
            spec.delete(spec.joint(f"{side}_{name}_joint"))
    return saved_without_controls(spec, tmp_path / "point_feet.xml")


def test_a_leg_that_ends_at_its_knee_has_its_ankle_at_its_foot(tmp_path):
    """With nothing jointed past the knee, the ankle keypoint is where the leg reaches the floor,
    a shin's length below the knee (it was the knee itself: Bolt's ankle at its knee, a fit
    of 9.7 cm, 6.8 once placed at the foot)."""
    robot = load_robot(_point_feet(tmp_path))
    plain = load_robot(robot_mjcf("g1"))
    for side in SIDES:
        knee = robot.rest_keypoints[robot.keypoint_index(f"{side}_knee")]
        ankle = robot.rest_keypoints[robot.keypoint_index(f"{side}_ankle")]
        shin = np.linalg.norm(
            plain.rest_keypoints[plain.keypoint_index(f"{side}_knee")]
            - plain.rest_keypoints[plain.keypoint_index(f"{side}_ankle")]
        )
        assert np.linalg.norm(knee - ankle) > 0.9 * shin, side
        assert ankle[2] - robot.floor_z < 0.05, side
