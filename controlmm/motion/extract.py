"""Global joints -> HumanML3D features: the full HumanML3D processing (``process_file``).

Steps (see docs/motion-representation.md): uniform skeleton, floor, XZ origin, face +Z,
foot contacts, IK for local rotations, root rotation/linear velocity, root height, RIC,
6-D rotations, local velocities. NumPy, float64 internally.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from controlmm.errors import ShapeError
from controlmm.motion.quaternion import qbetween, qinv, qmul, qrot, quat_to_cont6d
from controlmm.motion.skeleton import (
    FACE_JOINTS,
    FOOT_JOINTS_LEFT,
    FOOT_JOINTS_RIGHT,
    KINEMATIC_CHAINS,
    NUM_JOINTS,
    PARENTS,
    RAW_OFFSETS,
    TARGET_OFFSETS,
)

FOOT_CONTACT_THRESHOLD: float = 0.002
"""Squared per-frame displacement (m^2) below which a foot joint is in contact."""

_UP = np.array([0.0, 1.0, 0.0])
_FORWARD = np.array([0.0, 0.0, 1.0])


def check_joints(joints: np.ndarray, min_frames: int = 2) -> np.ndarray:
    """Validate a joint array (T, 22, 3): shape, finiteness, length. Returns float64 copy."""
    arr = np.asarray(joints)
    if arr.ndim != 3 or arr.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"joints must have shape (T, {NUM_JOINTS}, 3); got {arr.shape}")
    if arr.shape[0] < min_frames:
        raise ShapeError(f"joints need at least {min_frames} frames; got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ShapeError(f"joints contain NaN/inf (first at frame {bad[0]}, joint {bad[1]})")
    return arr.astype(np.float64, copy=True)


def _across(joints: np.ndarray, quirk: bool) -> np.ndarray:
    r_hip, l_hip, r_sh, l_sh = FACE_JOINTS
    if quirk:
        # HumanML3D's inverse_kinematics_np unpacks the face joints as (l_hip, r_hip, ...):
        # across = (L_hip - R_hip) + (R_sh - L_sh). Reproduced as-is.
        across = (joints[..., l_hip, :] - joints[..., r_hip, :]) + (
            joints[..., r_sh, :] - joints[..., l_sh, :]
        )
    else:
        across = (joints[..., r_hip, :] - joints[..., l_hip, :]) + (
            joints[..., r_sh, :] - joints[..., l_sh, :]
        )
    return across / np.linalg.norm(across, axis=-1, keepdims=True)


def inverse_kinematics(joints: np.ndarray, smooth_forward: bool) -> np.ndarray:
    """HumanML3D IK: per-joint local quaternions (T, 22, 4) from positions (T, 22, 3).

    The root rotation (index 0) turns the facing direction to +Z (forced to identity at
    frame 0); every other rotation is stored at the child joint and is the swing-only
    rotation of the bone parent -> child relative to the accumulated parent rotation.
    """
    forward = np.cross(_UP, _across(joints, quirk=True))
    if smooth_forward:
        forward = gaussian_filter1d(forward, 20, axis=0, mode="nearest")
    forward = forward / np.linalg.norm(forward, axis=-1, keepdims=True)
    root_quat = qbetween(forward, np.broadcast_to(_FORWARD, forward.shape))
    root_quat[0] = (1.0, 0.0, 0.0, 0.0)
    quats = np.zeros(joints.shape[:-1] + (4,))
    quats[..., 0] = 1.0
    quats[:, 0] = root_quat
    for chain in KINEMATIC_CHAINS:
        rot = root_quat
        for parent, child in zip(chain[:-1], chain[1:], strict=True):
            bone = joints[:, child] - joints[:, parent]
            bone = bone / np.linalg.norm(bone, axis=-1, keepdims=True)
            swing = qbetween(np.broadcast_to(RAW_OFFSETS[child], bone.shape), bone)
            local = qmul(qinv(rot), swing)
            quats[:, child] = local
            rot = qmul(rot, local)
    return quats


def uniform_skeleton(joints: np.ndarray, target_offsets: np.ndarray = TARGET_OFFSETS) -> np.ndarray:
    """Re-target positions onto the reference skeleton (T, 22, 3) -> (T, 22, 3).

    Every bone keeps its per-frame direction and gets the reference length; the root path
    is scaled by the leg-length ratio (right thigh + shin), as HumanML3D does.
    """
    src_len = np.linalg.norm(joints[0, 1:] - joints[0, list(PARENTS[1:])], axis=-1)
    src_len = np.concatenate([[0.0], src_len])
    tgt_len = np.linalg.norm(target_offsets, axis=-1)
    scale = (tgt_len[5] + tgt_len[8]) / (src_len[5] + src_len[8])
    out = np.empty_like(joints)
    out[:, 0] = joints[:, 0] * scale
    for chain in KINEMATIC_CHAINS:
        for parent, child in zip(chain[:-1], chain[1:], strict=True):
            bone = joints[:, child] - joints[:, parent]
            norm = np.linalg.norm(bone, axis=-1, keepdims=True)
            direction = np.where(norm > 1e-12, bone / np.maximum(norm, 1e-12), RAW_OFFSETS[child])
            out[:, child] = out[:, parent] + direction * tgt_len[child]
    return out


def canonicalize(joints: np.ndarray, uniform: bool = True) -> np.ndarray:
    """Uniform skeleton, floor at y = 0, frame-0 root at the XZ origin, frame 0 facing +Z.

    Returns HumanML3D "global positions" (T, 22, 3), the positions ControlMM controls.
    """
    pos = uniform_skeleton(joints) if uniform else joints.copy()
    pos[..., 1] -= pos[..., 1].min()
    pos -= pos[0, 0] * np.array([1.0, 0.0, 1.0])
    forward = np.cross(_UP, _across(pos[0], quirk=False))
    forward /= np.linalg.norm(forward)
    return qrot(np.broadcast_to(qbetween(forward, _FORWARD), pos.shape[:-1] + (4,)), pos)


def foot_contacts(positions: np.ndarray, threshold: float = FOOT_CONTACT_THRESHOLD) -> np.ndarray:
    """Binary contacts (T-1, 4) for joints (left_ankle, left_foot, right_ankle, right_foot)."""
    idx = list(FOOT_JOINTS_LEFT) + list(FOOT_JOINTS_RIGHT)
    disp = ((positions[1:, idx] - positions[:-1, idx]) ** 2).sum(-1)
    return (disp < threshold).astype(np.float64)


def joints_to_features(
    joints: np.ndarray, uniform: bool = True, regulate_turn_sign: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """HumanML3D ``process_file``: joints (T, 22, 3) -> features (T-1, 263).

    Args:
        joints: global joint positions in metres, Y up, any placement and heading.
        uniform: re-target onto the reference skeleton first (HumanML3D does).
        regulate_turn_sign: repair HumanML3D issue #156. The root rotation velocity is
            ``arcsin(q_delta.y)`` of ``q_delta = r_{t+1} r_t^-1``; once the facing passes 180
            degrees from frame 0 the root quaternions change hemisphere, ``q_delta`` gets
            w < 0 and that frame's velocity the wrong sign, so recovered joints jump. With
            the flag, ``q_delta`` is taken with w >= 0 (the same rotation); every other
            channel is unchanged. ``False`` reproduces the published code bit for bit.

    Returns:
        features: (T-1, 263) float32 feature vectors.
        positions: (T, 22, 3) the canonical global positions the features describe.
    """
    joints = check_joints(joints)
    positions = canonicalize(joints, uniform=uniform)
    contacts = foot_contacts(positions)

    quats = inverse_kinematics(positions, smooth_forward=True)
    cont6d = quat_to_cont6d(quats)
    r_rot = quats[:, 0]

    velocity = qrot(r_rot[1:], positions[1:, 0] - positions[:-1, 0])
    r_velocity = qmul(r_rot[1:], qinv(r_rot[:-1]))
    if regulate_turn_sign:
        r_velocity = np.where(r_velocity[:, :1] < 0.0, -r_velocity, r_velocity)
    rot_vel = np.arcsin(np.clip(r_velocity[:, 2:3], -1.0, 1.0))

    local = positions.copy()
    local[..., 0] -= local[:, 0:1, 0]
    local[..., 2] -= local[:, 0:1, 2]
    local = qrot(np.repeat(r_rot[:, None], NUM_JOINTS, axis=1), local)

    root_y = local[:, 0, 1:2]
    ric = local[:, 1:].reshape(len(local), -1)
    rot = cont6d[:, 1:].reshape(len(cont6d), -1)
    local_vel = qrot(np.repeat(r_rot[:-1, None], NUM_JOINTS, axis=1), positions[1:] - positions[:-1])

    features = np.concatenate(
        [
            rot_vel,
            velocity[:, [0, 2]],
            root_y[:-1],
            ric[:-1],
            rot[:-1],
            local_vel.reshape(len(local_vel), -1),
            contacts,
        ],
        axis=-1,
    )
    return features.astype(np.float32), positions
