"""Planned joints -> HumanML3D features and joints, as written to the corpus.

``joints_to_features`` reproduces HumanML3D's processing exactly, including a known flaw
(HumanML3D issue #156): the root rotation velocity is ``arcsin(q_delta.y)`` of
``q_delta = r_{t+1} r_t^-1``, and when the facing passes 180 degrees from the first frame
the root quaternions flip hemisphere, ``q_delta`` comes out with w < 0 and the velocity of
that one frame gets the wrong sign. Recovered joints then jump (the whole body turns by
twice that frame's rotation). Turning families cross 180 degrees, so the corpus repairs
feature 0 (taking the quaternion with w >= 0, which is the same rotation); every other
channel is unaffected because ``qrot(q, v) == qrot(-q, v)``.
"""

from __future__ import annotations

import numpy as np

from controlmm.motion import features_to_joints_np, joints_to_features
from controlmm.motion.extract import inverse_kinematics
from controlmm.motion.quaternion import qinv, qmul


def root_rotation_velocity(positions: np.ndarray) -> np.ndarray:
    """HumanML3D feature 0 (half the per-frame yaw increment, rad) of canonical positions
    (T, 22, 3), with the quaternion sign regulated: (T-1,)."""
    r_rot = inverse_kinematics(positions, smooth_forward=True)[:, 0]
    delta = qmul(r_rot[1:], qinv(r_rot[:-1]))
    delta = np.where(delta[:, :1] < 0.0, -delta, delta)
    return np.arcsin(np.clip(delta[:, 2], -1.0, 1.0))


def process(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planned joints (T+1, 22, 3) -> features (T, 263) float32, the joints those features
    describe (T, 22, 3) float32 (``features_to_joints``) and the canonical positions
    (T+1, 22, 3) float64 they must reproduce."""
    features, positions = joints_to_features(raw)
    features[:, 0] = root_rotation_velocity(positions).astype(np.float32)
    joints = features_to_joints_np(features).astype(np.float32)
    return features, joints, positions
