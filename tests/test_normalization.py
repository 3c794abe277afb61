import numpy as np
import pytest
import torch

from controlmm.errors import InputFileError
from controlmm.motion.normalization import FEATURE_GROUPS, Normalizer, group_std


def test_real_statistics_round_trip(humanml3d_dir, sample_features):
    norm = Normalizer.load(humanml3d_dir / "Mean.npy", humanml3d_dir / "Std.npy")
    x = norm.normalize(sample_features)
    assert np.allclose(norm.denormalize(x), sample_features, atol=1e-5)
    t = norm.normalize(torch.tensor(sample_features, dtype=torch.float64))
    assert t.dtype == torch.float64 and np.allclose(t.numpy(), x, atol=1e-5)
    # HumanML3D's Std is constant within each feature group.
    for sl in FEATURE_GROUPS.values():
        assert np.allclose(norm.std[sl], norm.std[sl][0])


def test_feat_bias_divides_root_and_contact_std(humanml3d_dir):
    norm = Normalizer.load(humanml3d_dir / "Mean.npy", humanml3d_dir / "Std.npy")
    biased = norm.with_feat_bias()
    assert np.allclose(biased.std[0:4], norm.std[0:4] / 25)
    assert np.allclose(biased.std[259:], norm.std[259:] / 25)
    assert np.array_equal(biased.std[4:259], norm.std[4:259])


def test_group_std(sample_features):
    mean, std = group_std(sample_features)
    assert np.allclose(mean, sample_features.mean(0))
    assert np.allclose(std[4:67], sample_features[:, 4:67].std(0).mean())


def test_missing_and_bad_statistics(tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        Normalizer.load(tmp_path / "Mean.npy", tmp_path / "Std.npy")
    with pytest.raises(InputFileError, match="263"):
        Normalizer(np.zeros(10), np.ones(10))
