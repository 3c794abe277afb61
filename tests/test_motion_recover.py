import numpy as np
import pytest
import torch

from controlmm.errors import ShapeError
from controlmm.motion.recover import features_to_joints, features_to_joints_np


def test_numpy_matches_reference_joints(sample_features, sample_joints):
    rec = features_to_joints_np(sample_features)
    assert rec.dtype == np.float32
    assert rec.shape == sample_joints.shape
    assert np.abs(rec - sample_joints).max() < 1e-4


def test_torch_float32_and_float64_match_reference(sample_features, sample_joints):
    for dtype in (torch.float32, torch.float64):
        rec = features_to_joints(torch.tensor(sample_features, dtype=dtype))
        assert rec.dtype == dtype
        assert (rec - torch.tensor(sample_joints, dtype=dtype)).abs().max().item() < 1e-4


def test_batched_equals_unbatched(sample_features, sample_joints):
    feats = torch.tensor(sample_features)
    other = feats.clone()
    other[:, 0] += 0.01  # a different clip: turning
    batch = torch.stack([feats, other]).reshape(1, 2, *feats.shape)
    out = features_to_joints(batch)
    assert out.shape == (1, 2, feats.shape[0], 22, 3)
    assert (out[0, 0] - torch.tensor(sample_joints)).abs().max().item() < 1e-4
    assert torch.allclose(out[0, 1], features_to_joints(other), atol=1e-6)
    assert (out[0, 1] - out[0, 0]).abs().max() > 0.1
    # Prefix property: the first n frames depend only on the first n feature rows.
    assert torch.allclose(features_to_joints(feats[:50]), features_to_joints(feats)[:50], atol=1e-6)


def test_only_first_67_channels_matter(sample_features):
    feats = torch.tensor(sample_features)
    noisy = feats.clone()
    noisy[:, 67:] = torch.randn_like(noisy[:, 67:])
    assert torch.equal(features_to_joints(feats), features_to_joints(noisy))


def test_gradcheck_short_clip(sample_features):
    feats = torch.tensor(sample_features[:6], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(features_to_joints, (feats,), eps=1e-6, atol=1e-5)


def test_gradient_reaches_every_root_channel(sample_features):
    feats = torch.tensor(sample_features[:20], requires_grad=True)
    features_to_joints(feats)[-1, 21].sum().backward()
    grad = feats.grad
    assert grad[:, 0].abs().sum() > 0  # rotation velocity
    assert grad[:, 1:3].abs().sum() > 0  # linear velocity
    assert grad[-1, 4 + 20 * 3 : 4 + 21 * 3].abs().sum() > 0  # right wrist RIC


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_cuda_matches_cpu(sample_features):
    feats = torch.tensor(sample_features)
    assert torch.allclose(features_to_joints(feats.cuda()).cpu(), features_to_joints(feats), atol=1e-5)


def test_bad_shape_is_one_line_error():
    with pytest.raises(ShapeError, match=r"\(\.\.\., T, 263\)"):
        features_to_joints(torch.zeros(10, 262))
