"""Calibration of the default checks on what the retargeter produces.

The real HumanML3D clip, retargeted to G1, passes the default :class:`CheckConfig` in the
empty scene; the same trajectory with one deliberate defect (a hand through the torso, the
robot sunk 3 cm into the floor, a joint past its limit, a stance foot sliding 10 cm, the
pelvis teleported) fails, with an error of the right kind. The corpus-wide figures are in
``benchmarks/sim_calibration.py`` / docs/BENCHMARKS.md.
"""

from __future__ import annotations

import numpy as np
import pytest

from controlmm.motion import Motion
from retarget import retarget_motion
from scenes import load_scene
from sim import check_trajectory, make_world


@pytest.fixture(scope="module")
def world():
    return make_world(load_scene("empty", robot="g1"))


@pytest.fixture(scope="module")
def clean(sample_features):
    """(qpos (T, 36) at 50 fps, joint names) of HumanML3D 012314 retargeted to G1."""
    traj = retarget_motion(Motion.from_features(sample_features), "g1", fps=50.0, metrics=False)
    return traj.qpos, traj.joint_names


def _errors(report) -> set[str]:
    return {f.kind for f in report.failures if f.is_error}


def _col(names: list[str], joint: str) -> int:
    return 7 + names.index(joint)


def _ease(n: int) -> np.ndarray:
    """0 -> 1 -> 0 over n frames (smooth, no velocity spike)."""
    return np.sin(np.linspace(0.0, np.pi, n)) ** 2


def test_clean_retargeted_clip_passes(world, clean):
    qpos, _ = clean
    report = check_trajectory(world, qpos, 50.0)
    assert report.passed, report.summary()
    assert report.floor_penetration_m < 0.005 and report.self_collision_frames == 0
    assert report.joint_limit_violations == 0


def test_hand_through_the_torso_fails(world, clean):
    qpos, names = clean
    q = qpos.copy()
    span = slice(200, 250)
    # right arm swung across the chest: shoulder roll towards the body, elbow bent in
    q[span, _col(names, "right_shoulder_roll_joint")] += 1.4 * _ease(50)
    q[span, _col(names, "right_shoulder_yaw_joint")] += 1.0 * _ease(50)
    q[span, _col(names, "right_elbow_joint")] += 0.8 * _ease(50)
    lo, hi = world.joints.lower, world.joints.upper
    q[:, 7:] = np.clip(q[:, 7:], lo, hi)
    report = check_trajectory(world, q, 50.0)
    hits = [f for f in report.failures_of("self_collision") if f.is_error]
    assert hits and not report.passed
    assert all(200 <= f.frame_start and f.frame_end < 250 for f in hits)
    assert any("right" in f.robot_body or "right" in f.obstacle_geom for f in hits)


def test_feet_3cm_below_the_floor_fail(world, clean):
    qpos, _ = clean
    q = qpos.copy()
    q[100:160, 2] -= 0.03 * np.minimum(1.0, np.minimum(np.arange(60), np.arange(60)[::-1]) / 5.0)
    report = check_trajectory(world, q, 50.0)
    hits = [f for f in report.failures_of("floor_penetration") if f.is_error]
    assert hits and not report.passed
    assert max(f.depth for f in hits) > 0.025
    assert all(100 <= f.frame_start and f.frame_end < 160 for f in hits)


def test_joint_beyond_its_limit_fails(world, clean):
    qpos, names = clean
    q = qpos.copy()
    c = _col(names, "left_elbow_joint")
    j = names.index("left_elbow_joint")
    upper = world.joints.upper[j]
    q[150:200, c] = np.maximum(q[150:200, c], upper - 0.2 + 0.3 * _ease(50))  # 0.1 rad past the limit
    report = check_trajectory(world, q, 50.0)
    hits = report.failures_of("joint_limit")
    assert hits and all(f.is_error and f.joint == "left_elbow_joint" for f in hits) and not report.passed
    assert max(f.depth for f in hits) == pytest.approx(0.1, abs=1e-3)


def test_stance_foot_sliding_10cm_fails(world, clean):
    qpos, _ = clean
    q = qpos.copy()
    report = check_trajectory(world, q, 50.0)
    stance = np.all([report.frames[f"foot_stance:{f.name}"] for f in world.feet], axis=0)  # both feet down
    start = int(np.flatnonzero(stance)[0])
    n = 25  # the whole robot glides 10 cm in 0.5 s while standing
    q[start : start + n, 0] += 0.10 * (0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n)))
    q[start + n :, 0] += 0.10
    report = check_trajectory(world, q, 50.0)
    hits = report.failures_of("foot_sliding")
    assert hits and all(f.is_error for f in hits) and not report.passed
    assert all(start <= f.frame_start and f.frame_end < start + n for f in hits)


def test_teleported_pelvis_fails(world, clean):
    qpos, _ = clean
    q = qpos.copy()
    q[300:, 1] += 0.3  # the robot jumps 30 cm sideways between two frames
    report = check_trajectory(world, q, 50.0)
    assert not report.passed
    slides = report.failures_of("foot_sliding")
    assert {f.robot_body for f in slides} == {f.name for f in world.feet}
    assert all(
        (f.frame_start, f.frame_end) == (300, 300) and f.depth == pytest.approx(0.3, abs=1e-3) for f in slides
    )
    # the sustained dynamic checks see the impulse too, within their 0.5 s window of frame 300
    assert all(300 - 13 <= f.frame_start and f.frame_end <= 300 + 13 for f in report.failures if f.is_error)
