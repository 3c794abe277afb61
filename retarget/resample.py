"""Time resampling of robot trajectories: cubic splines for positions and joints, SLERP for the root.

Joint angles and the root position use one cubic spline per channel (C2: no velocity kinks
at the input frames, unlike linear interpolation). A spline is linear in the samples with
the same weights for every channel, so the joints stay coordinated: a foot held still at
the input frames stays still in between (a shape-preserving PCHIP, whose weights depend on
each channel's data, made planted feet wobble by ~1 mm per output frame). Joint values are
clipped to the limits afterwards (splines may overshoot). The root orientation uses SLERP.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp


def output_times(num_frames: int, src_fps: float, dst_fps: float) -> np.ndarray:
    """Times (s) of the output frames: k / dst_fps up to the last input frame's time."""
    duration = (num_frames - 1) / src_fps
    count = int(np.floor(duration * dst_fps + 1e-9)) + 1
    return np.arange(count) / dst_fps


def interpolate_values(values: np.ndarray, src_fps: float, times: np.ndarray) -> np.ndarray:
    """Cubic-spline interpolation of (T, ...) samples at ``times`` (s); T == 1 repeats the frame."""
    if len(values) == 1:
        return np.repeat(values, len(times), axis=0)
    src = np.arange(len(values)) / src_fps
    if len(values) == 2:
        flat = values.reshape(2, -1)
        w = np.clip(times / src[1], 0, 1)[:, None]
        return ((1 - w) * flat[0] + w * flat[1]).reshape((len(times),) + values.shape[1:])
    return CubicSpline(src, values, axis=0)(np.clip(times, 0, src[-1]))


def slerp_quaternions(quat_wxyz: np.ndarray, src_fps: float, times: np.ndarray) -> np.ndarray:
    """SLERP of unit quaternions (T, 4) wxyz at ``times`` (s) -> (N, 4) wxyz."""
    if len(quat_wxyz) == 1:
        return np.repeat(quat_wxyz, len(times), axis=0)
    src = np.arange(len(quat_wxyz)) / src_fps
    rot = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]])
    out = Slerp(src, rot)(np.clip(times, 0, src[-1])).as_quat()
    return out[:, [3, 0, 1, 2]]


def continuous_quaternions(quat_wxyz: np.ndarray) -> np.ndarray:
    """Flip signs so consecutive quaternions lie in the same hemisphere (first one has w >= 0)."""
    q = np.array(quat_wxyz, dtype=np.float64)
    if len(q) and q[0, 0] < 0:
        q[0] *= -1
    for i in range(1, len(q)):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] *= -1
    return q


def resample_qpos(
    qpos: np.ndarray, src_fps: float, dst_fps: float, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """Resample a free-base qpos trajectory (T, 7 + nj) from ``src_fps`` to ``dst_fps``.

    Root position and joints: cubic splines; root quaternion (wxyz): SLERP; joints clipped
    to ``[lower, upper]`` afterwards.
    """
    times = output_times(len(qpos), src_fps, dst_fps)
    pos = interpolate_values(qpos[:, 0:3], src_fps, times)
    quat = continuous_quaternions(slerp_quaternions(qpos[:, 3:7], src_fps, times))
    joints = np.clip(interpolate_values(qpos[:, 7:], src_fps, times), lower, upper)
    return np.concatenate([pos, quat, joints], axis=1)
