"""Keyframe tracks of moving (mocap) obstacles.

A scene MJCF stores the track of a mocap body ``NAME`` as custom numeric data
``controlmm.track.NAME``: rows of 8 numbers ``t x y z qw qx qy qz`` (seconds, world metres, a
MuJoCo wxyz quaternion), times strictly increasing::

    <custom>
      <numeric name="controlmm.track.cart" data="0 2 -2.5 0.5 1 0 0 0   5 2 2.5 0.5 0.7071 0 0 0.7071"/>
    </custom>

Between keys the position is interpolated linearly and the orientation by spherical linear
interpolation; before the first key and after the last the pose holds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from controlmm.errors import ControlMMError

TRACK_PREFIX = "controlmm.track."
Tensor = torch.Tensor


@dataclass(frozen=True)
class MocapTrack:
    """Keyframed pose of one mocap body.

    Attributes:
        body: name of the mocap body.
        times: (K,) increasing key times in seconds.
        pos: (K, 3) world positions (m).
        quat: (K, 4) unit quaternions, wxyz (consecutive keys on the same hemisphere).
    """

    body: str
    times: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    _tensors: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @classmethod
    def from_flat(cls, body: str, data: np.ndarray) -> MocapTrack:
        """Parse the flat custom-numeric layout (rows ``t x y z qw qx qy qz``)."""
        data = np.asarray(data, dtype=np.float64).reshape(-1)
        if len(data) == 0 or len(data) % 8:
            raise ControlMMError(
                f"track of mocap body '{body}' has {len(data)} numbers; expected rows of 8 "
                "(t x y z qw qx qy qz)"
            )
        rows = data.reshape(-1, 8)
        if not np.all(np.isfinite(rows)):
            raise ControlMMError(f"track of mocap body '{body}' holds NaN or inf")
        if np.any(np.diff(rows[:, 0]) <= 0):
            raise ControlMMError(
                f"track of mocap body '{body}' must have strictly increasing times; got {rows[:, 0].tolist()}"
            )
        quat = rows[:, 4:]
        norm = np.linalg.norm(quat, axis=1, keepdims=True)
        if np.any(norm < 1e-9):
            raise ControlMMError(f"track of mocap body '{body}' has a zero quaternion")
        quat = quat / norm
        for k in range(1, len(quat)):  # shortest arcs between consecutive keys
            if np.dot(quat[k - 1], quat[k]) < 0:
                quat[k] = -quat[k]
        return cls(body=body, times=rows[:, 0].copy(), pos=rows[:, 1:4].copy(), quat=quat)

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])

    def pose(self, t: Tensor) -> tuple[Tensor, Tensor]:
        """Interpolated pose at times ``t`` (any shape, seconds) -> pos (..., 3), quat (..., 4)."""
        key = (t.dtype, t.device)
        if key not in self._tensors:  # the keys as tensors, once per dtype and device
            self._tensors[key] = tuple(
                torch.as_tensor(v, dtype=t.dtype, device=t.device) for v in (self.times, self.pos, self.quat)
            )
        times, pos, quat = self._tensors[key]
        if len(times) == 1:
            return pos[0].expand(*t.shape, 3), quat[0].expand(*t.shape, 4)
        tc = t.clamp(times[0], times[-1])
        k = torch.searchsorted(times, tc.contiguous(), right=True).clamp(1, len(times) - 1)
        t0, t1 = times[k - 1], times[k]
        a = ((tc - t0) / (t1 - t0))[..., None]
        p = pos[k - 1] * (1 - a) + pos[k] * a
        return p, _slerp(quat[k - 1], quat[k], a)

    def pose_numpy(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Pose at one time (seconds): pos (3,), quat (4,) as float64 NumPy arrays."""
        p, q = self.pose(torch.tensor(float(t), dtype=torch.float64))
        return p.numpy(), q.numpy()


def _slerp(q0: Tensor, q1: Tensor, a: Tensor) -> Tensor:
    """Spherical interpolation between unit quaternions (..., 4) on the same hemisphere."""
    dot = (q0 * q1).sum(-1, keepdim=True).clamp(-1.0, 1.0)
    theta = torch.acos(dot)
    sin = torch.sin(theta)
    small = sin < 1e-6
    safe = torch.where(small, torch.ones_like(sin), sin)
    w0 = torch.where(small, 1 - a, torch.sin((1 - a) * theta) / safe)
    w1 = torch.where(small, a, torch.sin(a * theta) / safe)
    q = w0 * q0 + w1 * q1
    return q / torch.linalg.vector_norm(q, dim=-1, keepdim=True)


def quat_to_mat(q: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4), wxyz (MuJoCo's order)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(*q.shape[:-1], 3, 3)
