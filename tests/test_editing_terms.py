import pytest
import torch

from controlmm.control import LossTerm, total_loss
from controlmm.errors import ControlMMError


def test_total_loss_sums_weighted_terms_and_is_differentiable():
    joints = torch.randn(3, 8, 22, 3, requires_grad=True)
    height = LossTerm("height", lambda j: j[..., 1].clamp(min=0).mean((1, 2)), weight=2.0)
    wrist = LossTerm("wrist", lambda j: (j[:, -1, 21] - 1.0).square().sum(-1))
    loss = total_loss([height, wrist], joints)
    assert loss.shape == (3,)
    expected = 2.0 * joints[..., 1].clamp(min=0).mean((1, 2)) + (joints[:, -1, 21] - 1.0).square().sum(-1)
    assert torch.allclose(loss, expected)
    loss.sum().backward()
    assert joints.grad is not None and joints.grad[:, -1, 21].abs().sum() > 0
    assert torch.equal(total_loss([], joints), torch.zeros(3))


def test_wrong_shape_is_rejected():
    bad = LossTerm("bad", lambda j: j.sum())
    with pytest.raises(ControlMMError, match="bad"):
        bad(torch.zeros(2, 4, 22, 3))
