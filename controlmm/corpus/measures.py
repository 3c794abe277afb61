"""Geometric measures of one motion for the probes (person's own frame, metres, 20 fps)."""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy.ndimage import uniform_filter1d

from controlmm.errors import ControlMMError
from controlmm.motion import geometry as geo

PELVIS = 0


class Measures:
    """Geometric measures of one motion (joints (T, 22, 3), metres, Y up, 20 fps)."""

    def __init__(self, joints: np.ndarray, fps: float = 20.0) -> None:
        j = np.asarray(joints, dtype=np.float64)
        if j.ndim != 3 or j.shape[1:] != (22, 3) or len(j) < 10:
            raise ControlMMError(f"probes need joints of shape (T >= 10, 22, 3); got {j.shape}")
        self.j = j - np.array([0.0, j[..., 1].min(), 0.0])  # floor at y = 0
        self.fps = fps

    @cached_property
    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame forward and left unit vectors (smoothed over 5 frames)."""
        f, _ = geo.facing(self.j)
        f = uniform_filter1d(f, 5, axis=0, mode="nearest")
        f[:, 1] = 0.0
        f /= np.linalg.norm(f, axis=-1, keepdims=True)
        return f, np.cross(geo.UP, f)

    @cached_property
    def heading(self) -> np.ndarray:
        """Unwrapped heading (degrees), + to the left."""
        f, _ = self.frame
        return np.degrees(np.unwrap(np.arctan2(f[:, 0], f[:, 2])))

    @property
    def turn(self) -> float:
        """Heading change start -> end (degrees), + to the left."""
        return float(self.heading[-3:].mean() - self.heading[:3].mean())

    @cached_property
    def speed(self) -> np.ndarray:
        """Pelvis ground speed (T-1,), m/s, smoothed over 5 frames."""
        return geo.ground_speed(self.j, 0, self.fps, smooth=5)

    @property
    def cruise(self) -> float:
        """Typical travelling speed: median speed over frames above 60% of the top speed."""
        v = self.speed
        top = v.max()
        return float(np.median(v[v >= 0.6 * top])) if top > 0.05 else 0.0

    @cached_property
    def travel(self) -> tuple[float, float, float]:
        """Distance travelled along the current facing, to the current left, and path length (m)."""
        step = np.diff(self.j[:, 0], axis=0)
        step[:, 1] = 0.0
        f, left = self.frame
        fm, lm = 0.5 * (f[1:] + f[:-1]), 0.5 * (left[1:] + left[:-1])
        return float((step * fm).sum()), float((step * lm).sum()), float(np.linalg.norm(step, axis=-1).sum())

    def displacement(self, start: int = 0, end: int = -1) -> tuple[float, float]:
        """Pelvis displacement (forward, left) between two frames in the start frame's facing."""
        f, left = self.frame
        d = self.j[end, 0] - self.j[start, 0]
        return float(d @ f[start]), float(d @ left[start])

    def body(self, joint: int, origin: int = PELVIS) -> np.ndarray:
        """A joint relative to ``origin`` in the person's frame: (T, 3) as (left, up, forward)."""
        f, left = self.frame
        d = self.j[:, joint] - self.j[:, origin]
        return np.stack([(d * left).sum(-1), d[:, 1], (d * f).sum(-1)], -1)

    def above(self, joint: int, other: int) -> np.ndarray:
        """Height of ``joint`` above ``other`` per frame (m)."""
        return self.j[:, joint, 1] - self.j[:, other, 1]

    @cached_property
    def flights(self) -> list[tuple[int, int]]:
        """Frame ranges with both feet off the ground (at least 2 frames)."""
        return geo.segments(geo.flight_mask(self.j, 0.06), min_len=2)

    @property
    def pelvis_height(self) -> np.ndarray:
        return self.j[:, 0, 1]

    @cached_property
    def stand_height(self) -> float:
        """Highest pelvis height over the clip (m), smoothed over 5 frames: standing."""
        return float(uniform_filter1d(self.pelvis_height, 5, mode="nearest").max())

    @cached_property
    def trunk_pitch(self) -> np.ndarray:
        """Forward tilt (degrees, T) of the trunk (pelvis -> neck) from the vertical, + towards the facing."""
        f, _ = self.frame
        d = self.j[:, 12] - self.j[:, 0]
        return np.degrees(np.arctan2((d * f).sum(-1), d[:, 1]))

    @cached_property
    def level(self) -> np.ndarray:
        """Height (m, T) of the lowest foot joint (ankles, toes): the surface the person stands on."""
        return self.j[:, [7, 8, 10, 11], 1].min(1)

    def rise(self, frames: int = 5) -> float:
        """Change of :attr:`level` (m) from the first to the last ``frames`` frames (medians)."""
        return float(np.median(self.level[-frames:]) - np.median(self.level[:frames]))
