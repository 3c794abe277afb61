"""Scene geometry of a clip (a seat, a platform, stairs, an obstacle) as boxes.

Families that move on or around objects build them as :class:`Box` es in the world frame of the
planner (metres, Y up) and return them with the joints (:class:`~controlmm.corpus.family.Built`).
The corpus writes them into ``meta/<id>.json`` in the clip's own frame, the frame of
``new_joints``: HumanML3D's canonical frame (floor at y = 0, the frame-0 pelvis above the origin,
frame 0 facing +Z, the person's left +X), so scenes and probes can rebuild the objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controlmm.corpus.feet import Terrain


@dataclass(frozen=True)
class Box:
    """An axis-aligned box turned by ``yaw`` (rad) about +Y.

    Attributes:
        name: what it is ("seat", "platform", "step 1", "obstacle").
        center: (x, y, z) of the box centre (m).
        size: (width, height, depth) (m): width along the box's own x, depth along its z.
        yaw: heading of the box's +z (rad, + turns +z towards +x).
    """

    name: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float

    @property
    def top(self) -> float:
        """Height (m) of the top face."""
        return float(self.center[1] + 0.5 * self.size[1])

    def contains_xz(self, xz: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which ground points (N, 2) as (x, z) lie over the box's footprint grown by ``margin`` (N,)."""
        d = np.asarray(xz, dtype=np.float64) - np.array([self.center[0], self.center[2]])
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        local_x = c * d[:, 0] - s * d[:, 1]
        local_z = s * d[:, 0] + c * d[:, 1]
        return (np.abs(local_x) <= 0.5 * self.size[0] + margin) & (
            np.abs(local_z) <= 0.5 * self.size[2] + margin
        )


@dataclass(frozen=True)
class Scene:
    """The objects of a clip: ``kind`` ("seat", "platform", "stairs", "obstacle"), the boxes and
    the numbers a caption or a probe may use (``values``: seat height, step height and count...)."""

    kind: str
    boxes: tuple[Box, ...]
    values: dict[str, Any] = field(default_factory=dict)

    def terrain(self, margin: float = 0.0) -> Terrain:
        """Ground height under points: (N, 2) as (x, z) -> (N,), the highest box top over each
        point (0 off the boxes); ``margin`` grows every footprint (for swing clearance)."""

        def height(xz: np.ndarray) -> np.ndarray:
            xz = np.atleast_2d(np.asarray(xz, dtype=np.float64))
            out = np.zeros(len(xz))
            for box in self.boxes:
                out = np.where(box.contains_xz(xz, margin), np.maximum(out, box.top), out)
            return out

        return height

    def to_clip_frame(self, raw0: np.ndarray, canonical0: np.ndarray) -> dict[str, Any]:
        """JSON record of the scene in the clip's frame.

        ``raw0`` (22, 3) is the planner's first frame, ``canonical0`` (22, 3) the same frame after
        HumanML3D's processing (a turn about +Y, a shift; no scaling on the reference skeleton):
        the transform is fitted to them (least squares) and applied to every box."""
        a = raw0[:, [0, 2]] - raw0[:, [0, 2]].mean(0)
        b = canonical0[:, [0, 2]] - canonical0[:, [0, 2]].mean(0)
        # 2-D rotation taking a to b: angle of sum(a x b), sum(a . b).
        cross = float((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())
        dot = float((a * b).sum())
        angle = np.arctan2(cross, dot)  # rotation in the (x, z) plane, x towards z
        c, s = np.cos(angle), np.sin(angle)
        rot = np.array([[c, -s], [s, c]])
        shift_xz = canonical0[:, [0, 2]].mean(0) - rot @ raw0[:, [0, 2]].mean(0)
        shift_y = float((canonical0[:, 1] - raw0[:, 1]).mean())
        boxes = []
        for box in self.boxes:
            xz = rot @ np.array([box.center[0], box.center[2]]) + shift_xz
            # A turn by `angle` from x towards z lowers a heading measured from z towards x.
            yaw = float(np.arctan2(np.sin(box.yaw - angle), np.cos(box.yaw - angle)))
            boxes.append(
                {
                    "name": box.name,
                    "center": [_r(xz[0]), _r(box.center[1] + shift_y), _r(xz[1])],
                    "size": [_r(v) for v in box.size],
                    "yaw_deg": _r(np.degrees(yaw)),
                }
            )
        return {"kind": self.kind, "frame": "clip", "boxes": boxes, **self.values}


def _r(x: float) -> float:
    return float(round(float(x), 4))
