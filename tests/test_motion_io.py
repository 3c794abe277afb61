import numpy as np
import pytest

from controlmm.errors import InputFileError, ShapeError
from controlmm.motion import Motion, load_motion, save_motion
from controlmm.motion.bvh import read_bvh, write_bvh
from controlmm.motion.container import resample


def test_npy_features_and_joints_told_apart_by_shape(humanml3d_dir, sample_joints):
    feats = load_motion(humanml3d_dir / "new_joint_vecs" / "012314.npy")
    assert feats.features is not None and feats.num_frames == 170
    assert np.abs(feats.joints - sample_joints).max() < 1e-4
    joints = load_motion(humanml3d_dir / "new_joints" / "012314.npy")
    assert joints.features is None and np.array_equal(joints.joints, sample_joints)


def test_npz_round_trip_keeps_everything(tmp_path, sample_features):
    m = Motion.from_features(sample_features, text="a person walks", metadata={"seed": 3})
    m.extras["mask"] = np.ones((4, 2), dtype=bool)
    save_motion(m, tmp_path / "m.npz")
    back = load_motion(tmp_path / "m.npz")
    assert np.array_equal(back.joints, m.joints) and np.array_equal(back.features, m.features)
    assert back.text == "a person walks" and back.metadata == {"seed": 3} and back.fps == 20.0
    assert back.extras["mask"].shape == (4, 2)


def test_bvh_forward_kinematics_reproduces_joints(tmp_path, sample_joints):
    write_bvh(tmp_path / "m.bvh", sample_joints, fps=20)
    text = (tmp_path / "m.bvh").read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis") and "Frames: 170" in text
    joints, fps = read_bvh(tmp_path / "m.bvh")
    assert fps == pytest.approx(20.0)
    assert np.linalg.norm(joints - sample_joints, axis=-1).max() < 0.01


def test_bvh_of_generic_non_rigid_pose(tmp_path, sample_joints):
    # 1 mm joint noise: bone lengths vary and the pelvis triangle is not rigid, which a BVH
    # (fixed offsets) cannot express exactly; the error stays near the noise level.
    rng = np.random.default_rng(0)
    noisy = sample_joints + rng.normal(scale=0.001, size=sample_joints.shape).astype(np.float32)
    write_bvh(tmp_path / "n.bvh", noisy)
    joints, _ = read_bvh(tmp_path / "n.bvh")
    err = np.linalg.norm(joints - noisy, axis=-1)
    assert err.max() < 0.02 and err.mean() < 0.005


def test_npy_output_computes_features(tmp_path, sample_joints):
    save_motion(Motion(sample_joints), tmp_path / "f.npy")
    assert np.load(tmp_path / "f.npy").shape == (169, 263)
    save_motion(Motion(sample_joints), tmp_path / "j.npy", npy_kind="joints")
    assert np.load(tmp_path / "j.npy").shape == (170, 22, 3)


def test_from_joints_resamples_to_20_fps(sample_joints):
    fine = resample(sample_joints.astype(np.float64), 20, 60)
    assert len(fine) == 3 * (len(sample_joints) - 1) + 1
    m = Motion.from_joints(fine, fps=60)
    assert m.num_frames == len(sample_joints) - 1 and m.features is not None


def test_bad_inputs(tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        load_motion(tmp_path / "missing.npz")
    with pytest.raises(InputFileError, match="allowed"):
        load_motion(tmp_path / "motion.txt")
    np.save(tmp_path / "bad.npy", np.zeros((10, 5)))
    with pytest.raises(ShapeError, match=r"\(10, 5\)"):
        load_motion(tmp_path / "bad.npy")
    (tmp_path / "corrupt.npz").write_bytes(b"not a zip")
    with pytest.raises(InputFileError, match="not a valid NPZ file"):
        load_motion(tmp_path / "corrupt.npz")
    with pytest.raises(ShapeError, match="NaN"):
        Motion(np.full((3, 22, 3), np.nan))


def test_bvh_with_given_bone_frames_reproduces_joints(tmp_path, sample_joints):
    from scipy.spatial.transform import Rotation

    joints = sample_joints[:40]
    frames = Rotation.random(40 * 22, random_state=0).as_matrix().reshape(40, 22, 3, 3)
    path = tmp_path / "frames.bvh"
    write_bvh(path, joints, fps=20.0, units_per_metre=100.0, rotations=frames)
    assert path.read_text().count("CHANNELS 6") == 22  # every joint carries its position
    back, fps = read_bvh(path)
    assert fps == pytest.approx(20.0)
    assert np.abs(back / 100.0 - joints).max() < 1e-4  # read in the file's unit (cm)
    with pytest.raises(InputFileError, match="rotations must be"):
        write_bvh(tmp_path / "bad.bvh", joints, rotations=frames[:10])
