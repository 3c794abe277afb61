"""The one place where human (HumanML3D) and world (MuJoCo) frames meet.

Human frame: metres, **Y up**, the motion starts at the origin facing **+Z**, +X is the
person's left. World frame: MuJoCo, **Z up**, metres. The canonical mapping puts the
human's forward on world +X and the human's left on world +Y:

    p_world = (z, x, y)            (a proper rotation, det = +1)

A :class:`HumanToWorld` adds a uniform scale ``s`` (the retargeter's human -> robot size
ratio), a yaw ``theta`` about world Z and a world translation ``t``:

    p_world = R_z(theta) (s * C p_human) + t,   C = [[0,0,1],[1,0,0],[0,1,0]]

Everything that converts between the two frames calls this module, NumPy or torch.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeAlias, TypeVar, overload

import numpy as np

from controlmm.errors import ControlMMError

if TYPE_CHECKING:
    import torch


# Axis permutation human (x, y, z) -> world (z, x, y).
HUMAN_TO_WORLD_AXES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

Array: TypeAlias = "np.ndarray | torch.Tensor"
"""A NumPy array or a torch tensor. torch is not imported here (it is heavy and a tensor can
only exist once torch is loaded): :meth:`HumanToWorld._consts` finds it in ``sys.modules``."""
ArrayT = TypeVar("ArrayT", np.ndarray, "torch.Tensor")
"""Either array kind, the same one in and out."""


def human_to_world_axes(points: ArrayT) -> ArrayT:
    """Canonical axis change (..., 3) human (Y up) -> world (Z up): (x, y, z) -> (z, x, y)."""
    return points[..., [2, 0, 1]]


def world_to_human_axes(points: ArrayT) -> ArrayT:
    """Inverse of :func:`human_to_world_axes`: world (x, y, z) -> human (y, z, x)."""
    return points[..., [1, 2, 0]]


@dataclass(frozen=True)
class HumanToWorld:
    """Similarity transform from the human frame to the MuJoCo world frame.

    Attributes:
        scale: uniform scale applied to human positions (robot size / human size).
        yaw: rotation about world +Z in radians (0: the human's forward is world +X).
        translation: world position (m) of the human frame's origin, (3,).
    """

    scale: float = 1.0
    yaw: float = 0.0
    translation: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ControlMMError(f"scale must be a positive number; got {self.scale}")
        if not math.isfinite(self.yaw) or not all(math.isfinite(v) for v in self.translation):
            raise ControlMMError("yaw and translation must be finite")
        object.__setattr__(self, "translation", tuple(float(v) for v in self.translation))

    @property
    def rotation(self) -> np.ndarray:
        """World-from-human rotation (3, 3): R_z(yaw) @ C."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return rz @ HUMAN_TO_WORLD_AXES

    @overload
    def to_world(self, points: np.ndarray) -> np.ndarray: ...

    @overload
    def to_world(self, points: torch.Tensor) -> torch.Tensor: ...

    def to_world(self, points: Array) -> Array:
        """Human points (..., 3) -> world points (..., 3).

        Tensors (the editing losses call this at every step) take one fused multiply-add,
        p @ (s R)^T + t."""
        torch = sys.modules.get("torch")
        if torch is not None and isinstance(points, torch.Tensor):
            like = {"dtype": points.dtype, "device": points.device}
            matrix = torch.as_tensor((self.scale * self.rotation).T, **like)
            trans = torch.as_tensor(np.asarray(self.translation), **like)
            return torch.addmm(trans, points.reshape(-1, 3), matrix).reshape(points.shape)
        rot, trans = self._consts(points)
        return self.scale * points @ rot.T + trans

    @overload
    def to_human(self, points: np.ndarray) -> np.ndarray: ...

    @overload
    def to_human(self, points: torch.Tensor) -> torch.Tensor: ...

    def to_human(self, points: Array) -> Array:
        """World points (..., 3) -> human points (..., 3)."""
        rot, trans = self._consts(points)
        return ((points - trans) @ rot) / self.scale

    def distance_to_human(self, distance: Array | float) -> Array | float:
        """A world-frame length (m) expressed in human-frame units (divide by scale)."""
        return distance / self.scale

    def _consts(self, like: Array) -> tuple[Array, Array]:
        rot = self.rotation
        trans = np.asarray(self.translation)
        torch = sys.modules.get("torch")
        if torch is not None and isinstance(like, torch.Tensor):
            return (
                torch.as_tensor(rot, dtype=like.dtype, device=like.device),
                torch.as_tensor(trans, dtype=like.dtype, device=like.device),
            )
        return rot, trans
