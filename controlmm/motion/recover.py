"""Features -> global joints: the differentiable R(.) of the ControlMM paper (Eq. 4).

Implements HumanML3D's ``recover_root_rot_pos`` + ``recover_from_ric`` in torch, batched
over any leading dimensions, autograd-clean, float32/float64, CPU or CUDA. Only the first
67 feature channels (root velocity, root height, RIC positions) affect the result.
"""

from __future__ import annotations

import numpy as np
import torch

from controlmm.errors import ShapeError
from controlmm.motion.skeleton import FEATURE_DIM, NUM_JOINTS


def _check_features(features: torch.Tensor) -> None:
    if features.ndim < 2 or features.shape[-1] != FEATURE_DIM:
        raise ShapeError(f"features must have shape (..., T, {FEATURE_DIM}); got {tuple(features.shape)}")


def recover_root(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Root heading angle and root position from features.

    Args:
        features: (..., T, 263) HumanML3D features (not normalised).

    Returns:
        heading: (..., T) root yaw theta_t (rad); world = R(theta) local with
            x' = cos(theta) x - sin(theta) z, z' = sin(theta) x + cos(theta) z, so the root
            faces the world direction (-sin theta, 0, cos theta) (theta_0 = 0: facing +Z).
        root: (..., T, 3) root (pelvis) position in metres, Y up.
    """
    _check_features(features)
    rot_vel = features[..., 0]
    # Exclusive cumulative sum: a_0 = 0, a_t = sum_{k<t} rot_vel_k; heading theta = 2 a.
    half = torch.cumsum(rot_vel, dim=-1) - rot_vel
    heading = 2.0 * half
    cos, sin = torch.cos(heading), torch.sin(heading)
    # Root displacement d_t = linvel_{t-1} (d_0 = 0), expressed in the root facing frame.
    lin = features[..., :-1, 1:3]
    zero = torch.zeros_like(lin[..., :1, :])
    lin = torch.cat([zero, lin], dim=-2)
    dx, dz = lin[..., 0], lin[..., 1]
    # Rotate by the inverse root quaternion: x' = cos x - sin z, z' = sin x + cos z.
    wx = cos * dx - sin * dz
    wz = sin * dx + cos * dz
    root = torch.stack([torch.cumsum(wx, -1), features[..., 3], torch.cumsum(wz, -1)], dim=-1)
    return heading, root


def features_to_joints(features: torch.Tensor) -> torch.Tensor:
    """Recover global joint positions from HumanML3D features.

    Args:
        features: (..., T, 263) features (denormalised), any float dtype and device.

    Returns:
        (..., T, 22, 3) joint positions in metres (Y up, frame 0 root at x = z = 0 facing +Z).
    """
    heading, root = recover_root(features)
    ric = features[..., 4 : 4 + (NUM_JOINTS - 1) * 3]
    ric = ric.reshape(ric.shape[:-1] + (NUM_JOINTS - 1, 3))
    cos = torch.cos(heading)[..., None]
    sin = torch.sin(heading)[..., None]
    x, y, z = ric[..., 0], ric[..., 1], ric[..., 2]
    wx = cos * x - sin * z + root[..., None, 0]
    wz = sin * x + cos * z + root[..., None, 2]
    others = torch.stack([wx, y, wz], dim=-1)
    return torch.cat([root[..., None, :], others], dim=-2)


def features_to_joints_np(features: np.ndarray) -> np.ndarray:
    """NumPy convenience wrapper of :func:`features_to_joints`, (..., T, 263) -> (..., T, 22, 3).

    Computes in the input's float precision (float64 input stays float64).
    """
    arr = np.asarray(features)
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float32)
    with torch.no_grad():
        return features_to_joints(torch.from_numpy(np.ascontiguousarray(arr))).numpy()
