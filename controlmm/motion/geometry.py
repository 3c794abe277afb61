"""Geometric measures of human motion in the HumanML3D frame (metres, Y up, 20 fps).

The facing direction comes from the hips and shoulders: ``across = (R_hip - L_hip) +
(R_shoulder - L_shoulder)`` points from the person's left to their right, and
``forward = up x across``; ``left = up x forward``. The heading angle is
``atan2(forward_x, forward_z)``: 0 when facing +Z, increasing when the person turns to
their left (counter-clockwise seen from above). All functions take joints (T, 22, 3).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

UP = np.array([0.0, 1.0, 0.0])
FOOT_JOINTS = (10, 11)
SKATE_HEIGHT = 0.05
SKATE_SPEED = 0.5


def facing(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forward and left vectors in the ground plane, (T, 3) each."""
    j = np.asarray(joints, dtype=np.float64)
    across = (j[:, 2] - j[:, 1]) + (j[:, 17] - j[:, 16])
    across[:, 1] = 0.0
    across /= np.maximum(np.linalg.norm(across, axis=-1, keepdims=True), 1e-9)
    forward = np.cross(UP, across)
    left = np.cross(UP, forward)
    return forward, left


def ground_speed(joints: np.ndarray, joint: int = 0, fps: float = 20.0, smooth: int = 5) -> np.ndarray:
    """Horizontal speed (T-1,) of a joint in m/s, smoothed over ``smooth`` frames."""
    j = np.asarray(joints, dtype=np.float64)
    v = np.linalg.norm(np.diff(j[:, joint][:, [0, 2]], axis=0), axis=-1) * fps
    return uniform_filter1d(v, smooth, mode="nearest") if smooth > 1 else v


def floor_height(joints: np.ndarray) -> float:
    """The floor: the lowest point of any joint over the clip (0 for HumanML3D data)."""
    return float(np.asarray(joints)[..., 1].min())


def flight_mask(joints: np.ndarray, clearance: float = 0.06) -> np.ndarray:
    """Frames (T,) where all four foot joints (ankles, toes) are more than ``clearance`` above
    their own lowest height over the clip, i.e. both feet are off the ground."""
    j = np.asarray(joints, dtype=np.float64)
    feet = j[:, [7, 8, 10, 11], 1]
    return np.all(feet > feet.min(0) + clearance, axis=-1)


def segments(mask: np.ndarray, min_len: int = 1) -> list[tuple[int, int]]:
    """Runs of True in a boolean array as (start, end) with end exclusive, at least ``min_len`` long."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    runs = [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return [r for r in runs if r[1] - r[0] >= min_len]


def foot_skating_ratio(joints: np.ndarray, fps: float = 20.0) -> float:
    """Foot-skating ratio of the spatial-control evaluation (the "Foot Skating Ratio" of OmniControl
    and ControlMM, Table 1 of "ControlMM: Controllable Masked Motion Generation", 2024).

    Feet = joints 10 and 11; v_t = planar speed (m/s) between t and t+1; v_bar = its 5-frame
    moving average (zero padded); a foot is in contact when its height is below 0.05 m at
    t and t+1; frame t skates when, for either foot, contact and v_t > 0.5 and v_bar_t > 0.5.
    Returns skating frames / (T - 1).
    """
    j = np.asarray(joints, dtype=np.float64)
    feet = j[:, list(FOOT_JOINTS)]
    v = np.linalg.norm(np.diff(feet[:, :, [0, 2]], axis=0), axis=-1) * fps
    v_bar = uniform_filter1d(v, 5, axis=0, mode="constant")
    low = feet[:, :, 1] < SKATE_HEIGHT
    contact = low[:-1] & low[1:]
    skate = np.any(contact & (v > SKATE_SPEED) & (v_bar > SKATE_SPEED), axis=-1)
    return float(skate.sum() / max(len(j) - 1, 1))


def oscillations(signal: np.ndarray, min_amplitude: float) -> int:
    """Number of monotone swings of a 1-D signal between turning points that each span at
    least ``min_amplitude`` (hysteresis): n back-and-forth cycles give about 2n swings."""
    x = np.asarray(signal, dtype=np.float64)
    if len(x) < 2:
        return 0
    count, direction, anchor, extreme = 0, 0.0, x[0], x[0]
    for value in x[1:]:
        if direction == 0.0:
            if abs(value - anchor) >= min_amplitude:
                direction, extreme = float(np.sign(value - anchor)), value
            continue
        if direction * (value - extreme) > 0:
            extreme = value
        elif direction * (extreme - value) >= min_amplitude:
            count += 1
            anchor, extreme, direction = extreme, value, -direction
    if direction != 0.0 and abs(extreme - anchor) >= min_amplitude:
        count += 1
    return count


def count_dips(signal: np.ndarray, low: float, high: float) -> int:
    """Count excursions of a signal below ``low`` that are separated by returns above ``high``
    (hysteresis thresholds, low < high)."""
    count, armed = 0, True
    for value in np.asarray(signal, dtype=np.float64):
        if armed and value < low:
            count += 1
            armed = False
        elif not armed and value > high:
            armed = True
    return count
