"""Resampling (cubic splines + SLERP), human stance detection and the mink baseline."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from controlmm.motion import Motion
from retarget import retarget_motion
from retarget.resample import continuous_quaternions, output_times, resample_qpos
from retarget.stance import detect_stance


def test_output_times_cover_the_motion():
    assert len(output_times(170, 20, 50)) == 423  # 8.45 s
    assert len(output_times(170, 20, 30)) == 254
    assert len(output_times(1, 20, 50)) == 1
    np.testing.assert_allclose(output_times(5, 20, 40), np.arange(9) / 40)


def test_resample_qpos_joints_root_and_limits():
    t = np.arange(21) / 20.0
    yaw = 1.5 * t
    quat = Rotation.from_euler("z", yaw[:, None]).as_quat()[:, [3, 0, 1, 2]]
    joints = np.stack([np.sin(2 * t), np.where(t > 0.5, 1.0, 2 * t)], axis=1)  # the 2nd sits on its limit
    qpos = np.concatenate([np.stack([t, 0 * t, 0.8 + 0 * t], 1), quat, joints], axis=1)
    out = resample_qpos(qpos, 20.0, 50.0, lower=np.array([-2.0, -1.0]), upper=np.array([2.0, 1.0]))
    times = np.arange(len(out)) / 50.0
    assert len(out) == 51
    np.testing.assert_allclose(out[:, 0], times, atol=1e-9)  # linear root path is reproduced
    np.testing.assert_allclose(out[:, 7], np.sin(2 * times), atol=2e-4)
    assert out[:, 8].max() <= 1.0  # the spline's overshoot near the kink is clipped to the limit
    got_yaw = Rotation.from_quat(out[:, [4, 5, 6, 3]]).as_euler("xyz")[:, 2]
    np.testing.assert_allclose(got_yaw, 1.5 * times, atol=1e-9)  # SLERP about one axis is exact
    # Every 5th output frame is an input frame (50 / 20 = 2.5).
    np.testing.assert_allclose(out[::5], qpos[::2], atol=1e-12)


def test_quaternions_are_made_continuous():
    q = np.array([[-1.0, 0, 0, 0], [0.99, 0.1, 0, 0], [-0.98, -0.2, 0, 0]])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = continuous_quaternions(q)
    assert out[0, 0] > 0 and np.all(np.sum(out[1:] * out[:-1], axis=1) > 0)


def test_stance_detection_on_the_real_clip(sample_joints):
    left = detect_stance(sample_joints, 20.0, "left")
    right = detect_stance(sample_joints, 20.0, "right")
    # The clip ends standing still on both feet and the feet are down most of the time.
    assert left[-20:].all() and right[-20:].all()
    assert 0.4 < left.mean() < 0.95 and 0.4 < right.mean() < 0.95
    # A foot high in the air is never in stance.
    ankle = sample_joints[:, 7, 1]
    assert not left[ankle > 0.15].any()


def test_mink_baseline_on_the_same_targets(sample_features):
    pytest.importorskip("mink")
    pytest.importorskip("daqp")
    motion = Motion.from_features(sample_features[:20])
    traj = retarget_motion(motion, "g1", solver="mink")
    assert traj.metrics["joint_limit_violations"] == 0
    assert traj.metrics["keypoint_error_mm"]["pelvis"]["mean"] < 80
    assert traj.solver["method"].startswith("mink")
