"""The :class:`Motion` container: human joints (metres, Y up) with optional features."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from controlmm.errors import ShapeError
from controlmm.motion.extract import check_joints, joints_to_features
from controlmm.motion.recover import features_to_joints_np
from controlmm.motion.skeleton import FEATURE_DIM, FPS, NUM_JOINTS


@dataclass
class Motion:
    """A human motion on the HumanML3D 22-joint skeleton.

    Attributes:
        joints: (T, 22, 3) float32 global joint positions, metres, Y up.
        fps: frames per second (HumanML3D motion is 20).
        features: optional (T, 263) HumanML3D features describing the same frames.
        text: the prompt or caption, if any.
        metadata: JSON-serialisable extra information (source, seed, control errors...).
        extras: extra named arrays saved alongside (e.g. a control mask).
    """

    joints: np.ndarray
    fps: float = float(FPS)
    features: np.ndarray | None = None
    text: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        joints = np.asarray(self.joints)
        if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
            raise ShapeError(f"joints must have shape (T, {NUM_JOINTS}, 3); got {joints.shape}")
        if joints.shape[0] < 1:
            raise ShapeError("a motion needs at least one frame")
        check_finite(joints, "joints")
        self.joints = joints.astype(np.float32, copy=False)
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ShapeError(f"fps must be a positive number; got {self.fps}")
        self.fps = float(self.fps)
        if self.features is not None:
            feats = np.asarray(self.features)
            if feats.shape != (joints.shape[0], FEATURE_DIM):
                raise ShapeError(
                    f"features must have shape ({joints.shape[0]}, {FEATURE_DIM}) to match the joints; "
                    f"got {feats.shape}"
                )
            check_finite(feats, "features")
            self.features = feats.astype(np.float32, copy=False)

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])

    @property
    def seconds(self) -> float:
        return self.num_frames / self.fps

    @classmethod
    def from_features(cls, features: np.ndarray, text: str = "", **kwargs: Any) -> Motion:
        """Build from HumanML3D features (T, 263); joints are recovered (20 fps)."""
        feats = np.asarray(features)
        if feats.ndim != 2 or feats.shape[1] != FEATURE_DIM:
            raise ShapeError(f"features must have shape (T, {FEATURE_DIM}); got {feats.shape}")
        if feats.shape[0] < 2:
            raise ShapeError(
                f"features need at least 2 frames (they hold velocities between frames); got {feats.shape[0]}"
            )
        check_finite(feats, "features")
        feats = feats.astype(np.float32)
        return cls(joints=features_to_joints_np(feats), fps=float(FPS), features=feats, text=text, **kwargs)

    @classmethod
    def from_joints(cls, joints: np.ndarray, fps: float = FPS, text: str = "", **kwargs: Any) -> Motion:
        """Import any joint sequence (T, 22, 3), metres, Y up, through HumanML3D processing.

        The motion is resampled to 20 fps if needed, re-targeted onto the reference
        skeleton and canonicalised (floor, origin, facing +Z). The result has T' - 1 frames
        (the features' length) and joints recovered from those features.
        """
        arr = check_joints(joints)
        if abs(fps - FPS) > 1e-6:
            arr = resample(arr, fps, FPS)
        feats, _ = joints_to_features(arr)
        return cls.from_features(feats, text=text, **kwargs)

    def with_features(self) -> Motion:
        """This motion with features; computes them (HumanML3D processing) when absent."""
        if self.features is not None:
            return self
        out = Motion.from_joints(self.joints, fps=self.fps, text=self.text)
        return replace(out, metadata=dict(self.metadata), extras=dict(self.extras))


def check_finite(values: np.ndarray, what: str) -> None:
    """A one-line ShapeError naming the first frame (axis 0) of ``values`` with NaN/inf."""
    bad = ~np.isfinite(values.reshape(values.shape[0], -1)).all(axis=1)
    if bad.any():
        frames = np.flatnonzero(bad)
        raise ShapeError(
            f"{what} contain NaN/inf at {len(frames)} frame(s), the first at frame {int(frames[0])}"
        )


def resample(joints: np.ndarray, src_fps: float, dst_fps: float) -> np.ndarray:
    """Linear resampling of positions (T, ..., 3) from ``src_fps`` to ``dst_fps``."""
    t = joints.shape[0]
    duration = (t - 1) / src_fps
    n = int(np.floor(duration * dst_fps + 1e-9)) + 1
    src_t = np.arange(t) / src_fps
    dst_t = np.arange(n) / dst_fps
    flat = joints.reshape(t, -1)
    out = np.stack([np.interp(dst_t, src_t, flat[:, k]) for k in range(flat.shape[1])], axis=-1)
    return out.reshape((n,) + joints.shape[1:])
