"""Planned joints -> HumanML3D features and joints, as written to the corpus.

The corpus uses the foundation's ``joints_to_features`` with its repair of HumanML3D issue
#156 (on by default): turning families pass 180 degrees, where the published processing
flips the sign of one frame's root rotation velocity and the recovered body jumps.
"""

from __future__ import annotations

import numpy as np

from controlmm.motion import features_to_joints_np, joints_to_features


def process(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planned joints (T+1, 22, 3) -> features (T, 263) float32, the joints those features
    describe (T, 22, 3) float32 (``features_to_joints``) and the canonical positions
    (T+1, 22, 3) float64 they must reproduce."""
    features, positions = joints_to_features(raw)
    joints = features_to_joints_np(features).astype(np.float32)
    return features, joints, positions
