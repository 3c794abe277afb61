"""The tokenizer's reconstruction loss on the real HumanML3D sample: which joints its extra terms
weigh, and that a head turned against the shoulders is no longer a small error."""

import numpy as np
import torch

from controlmm.models.config import preset_config
from controlmm.motion.recover import features_to_joints
from controlmm.motion.skeleton import JOINT_INDEX
from controlmm.training.tokenizer import HEAD, LIMB_ENDS, NECK, head_direction_loss, reconstruction_loss


def moved_joints(features: torch.Tensor, dims: list[int]) -> set[str]:
    """Names of the joints that ``features_to_joints`` moves when ``dims`` change."""
    shifted = features.clone()
    shifted[:, dims] += 0.05
    moved = (features_to_joints(shifted) - features_to_joints(features)).norm(dim=-1).amax(dim=0)
    return {name for name, i in JOINT_INDEX.items() if moved[i] > 1e-4}


def test_the_extra_terms_weigh_limb_ends_and_the_head(sample_features):
    feats = torch.tensor(sample_features)
    assert moved_joints(feats, LIMB_ENDS) == {
        "left_ankle", "right_ankle", "left_foot", "right_foot", "left_wrist", "right_wrist"
    }  # fmt: skip
    assert moved_joints(feats, NECK) == {"neck"}
    assert moved_joints(feats, HEAD) == {"head"}


def turn_head(features: torch.Tensor, degrees: float) -> torch.Tensor:
    """Features with the neck -> head vector of every frame turned about the vertical (Y) axis."""
    a = np.radians(degrees)
    rot = torch.tensor([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    out = features.clone()
    neck = out[:, NECK]
    out[:, HEAD] = neck + (out[:, HEAD] - neck) @ rot.T.to(out.dtype)
    return out


def test_a_head_turn_is_a_large_error(sample_features):
    feats = torch.tensor(sample_features)[None] / 0.1  # (1, T, 263) about normalised: RIC std ~0.1 m
    zero = torch.zeros(())
    assert float(head_direction_loss(feats, feats)) == 0.0
    small, large = (turn_head(feats[0], d)[None] for d in (20.0, 40.0))
    # Nearly L1: twice the turn, about twice the loss (a quadratic term would give four times).
    ratio = float(head_direction_loss(large, feats) / head_direction_loss(small, feats))
    assert 1.8 < ratio < 2.3
    # At the demo preset's weights the head term dominates the loss of a head turn; MoMask's terms
    # alone (the default weights, 0 and 0) barely see it.
    demo = preset_config("demo").schedules["tokenizer"]
    full = float(reconstruction_loss(large, feats, zero, demo.limb_end_weight, demo.head_weight))
    momask = float(reconstruction_loss(large, feats, zero))
    assert full > 20 * momask
