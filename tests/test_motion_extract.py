import numpy as np
import pytest

from controlmm.errors import ShapeError
from controlmm.motion.extract import foot_contacts, joints_to_features
from controlmm.motion.quaternion import qbetween, qrot
from controlmm.motion.recover import features_to_joints_np
from controlmm.motion.skeleton import BONE_LENGTHS, PARENTS


def test_round_trip_on_real_joints(sample_joints):
    feats, positions = joints_to_features(sample_joints)
    assert feats.shape == (len(sample_joints) - 1, 263)
    rec = features_to_joints_np(feats.astype(np.float64))
    err = np.linalg.norm(rec - sample_joints[:-1], axis=-1)
    assert err.max() < 0.01
    assert err.mean() < 0.001


def test_features_close_to_reference_features(sample_joints, sample_features):
    feats, _ = joints_to_features(sample_joints)
    ref = sample_features[:-1]
    # Root height, local velocities and contacts are recomputed exactly; RIC/rotations
    # differ only by the frame-0 heading smoothing HumanML3D applied on the raw clip.
    assert np.abs(feats[:, 3] - ref[:, 3]).max() < 1e-5
    assert np.abs(feats[:, 193:259] - ref[:, 193:259]).max() < 1e-3
    assert np.array_equal(feats[:, 259:], ref[:, 259:])
    assert np.abs(feats[:, 4:67] - ref[:, 4:67]).mean() < 1e-3


def _yaw(angle: float) -> np.ndarray:
    return qbetween(np.array([0.0, 0.0, 1.0]), np.array([np.sin(angle), 0.0, np.cos(angle)]))


def test_canonicalisation_removes_placement_heading_and_size(sample_joints):
    base, _ = joints_to_features(sample_joints)
    moved = qrot(
        np.broadcast_to(_yaw(1.1), sample_joints.shape[:-1] + (4,)), sample_joints.astype(np.float64)
    )
    moved = 1.3 * moved + np.array([4.0, 0.5, -2.0])
    feats, positions = joints_to_features(moved)
    assert np.abs(feats[:, :67] - base[:, :67]).max() < 1e-4
    # Reference skeleton: every bone has the reference length after processing.
    lengths = np.linalg.norm(positions[:, 1:] - positions[:, list(PARENTS[1:])], axis=-1)
    assert np.abs(lengths - BONE_LENGTHS[1:]).max() < 1e-6
    assert abs(positions[..., 1].min()) < 1e-9
    assert np.allclose(positions[0, 0, [0, 2]], 0.0)


def test_foot_contacts_follow_displacement():
    pos = np.zeros((5, 22, 3))
    pos[:, 10, 2] = [0.0, 0.01, 0.02, 0.2, 0.4]  # left toe: still, then moving fast
    contacts = foot_contacts(pos)
    assert contacts[:, 1].tolist() == [1.0, 1.0, 0.0, 0.0]
    assert contacts[:, 0].tolist() == [1.0] * 4


def test_bad_joints_rejected():
    with pytest.raises(ShapeError, match="shape"):
        joints_to_features(np.zeros((10, 21, 3)))
    bad = np.zeros((10, 22, 3))
    bad[3, 4, 1] = np.nan
    with pytest.raises(ShapeError, match="NaN"):
        joints_to_features(bad)


def test_full_turn_round_trips_with_the_turn_sign_repair(sample_joints):
    # Spin the real clip about its pelvis through two full turns (HumanML3D issue #156).
    t = len(sample_joints)
    angles = np.linspace(0.0, 4.0 * np.pi, t)
    quats = np.stack([_yaw(a) for a in angles])[:, None].repeat(22, axis=1)
    centre = sample_joints[:, :1] * np.array([1.0, 0.0, 1.0])
    spun = qrot(quats, sample_joints.astype(np.float64) - centre) + centre
    feats, positions = joints_to_features(spun)
    assert np.abs(features_to_joints_np(feats.astype(np.float64)) - positions[:-1]).max() < 1e-4
    plain, _ = joints_to_features(spun, regulate_turn_sign=False)
    assert np.abs(features_to_joints_np(plain.astype(np.float64)) - positions[:-1]).max() > 0.05
