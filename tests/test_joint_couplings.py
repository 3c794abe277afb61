"""Joints the MJCF couples (``<equality><joint>``): the retargeter keeps the coupling, validate checks it.

NAO's two hip yaw-pitch joints share one motor, written as ``joint1 = joint2``; here a G1
whose hip yaws are coupled as mirror images (``polycoef="0 -1 0 0 0"``) stands in for it.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from controlmm.motion import Motion
from retarget import load_robot, retarget_motion, robot_mjcf
from scenes import load_scene
from sim import check_trajectory

FPS = 30.0


def _coupled_g1(tmp_path: Path) -> Path:
    src = robot_mjcf("g1")
    spec = mujoco.MjSpec.from_file(str(src))
    spec.meshdir = str(src.parent / "assets")
    data = np.zeros(mujoco.mjNEQDATA)
    data[1] = -1.0  # left_hip_yaw = -right_hip_yaw
    spec.add_equality(
        type=mujoco.mjtEq.mjEQ_JOINT,
        objtype=mujoco.mjtObj.mjOBJ_JOINT,
        name1="left_hip_yaw_joint",
        name2="right_hip_yaw_joint",
        data=data,
    )
    path = tmp_path / "g1_coupled.xml"
    path.write_text(spec.to_xml())
    return path


@pytest.fixture(scope="module")
def motion(sample_features) -> Motion:
    return Motion.from_features(sample_features[:80])


def test_coupled_joints_keep_their_coupling_and_validate_checks_it(tmp_path, motion):
    path = _coupled_g1(tmp_path)
    robot = load_robot(path)
    assert robot.couplings is not None
    left, right = (robot.tree.joint_names.index(f"{s}_hip_yaw_joint") for s in ("left", "right"))
    assert (robot.couplings.first.tolist(), robot.couplings.second.tolist()) == ([left], [right])

    coupled = retarget_motion(motion, path, fps=FPS)
    q = coupled.qpos[:, 7:]
    np.testing.assert_allclose(q[:, left], -q[:, right], atol=1e-9)
    assert np.abs(q[:, right]).max() > 0.02  # the hips do turn: the coupling is not met by standing still
    # The fit stays near the plain G1's (the legs' own post-steps leave the coupled joints to
    # the solver, which turns both hips together).
    plain = retarget_motion(motion, "g1", fps=FPS)
    assert (
        coupled.metrics["keypoint_error_mm"]["all"]["mean"]
        < 1.2 * plain.metrics["keypoint_error_mm"]["all"]["mean"]
    )

    scene = load_scene("empty", robot=str(path))
    report = check_trajectory(scene, coupled.qpos, FPS)
    assert "joint_coupling" not in {f.kind for f in report.failures}
    # The plain G1's output turns its hips independently: on the coupled robot it fails.
    off = np.abs(plain.qpos[:, 7 + left] + plain.qpos[:, 7 + right])
    assert off.max() > 0.01
    bad = [f for f in check_trajectory(scene, plain.qpos, FPS).failures if f.kind == "joint_coupling"]
    assert bad and {f.joint for f in bad} == {"left_hip_yaw_joint"}
    assert max(f.depth for f in bad) == pytest.approx(off.max(), abs=1e-6)
