"""Mean/Std normalisation of HumanML3D features.

HumanML3D's ``Std.npy`` already holds the group-mean std of each feature group (root
rotation velocity, root linear velocity, root height, RIC, rotations, velocities,
contacts). MoMask's VQ training further divides the std of dims 0-3 and 259-262 by
``feat_bias`` (5, applied twice in the official code: Std/25). Use the statistics stored
with a checkpoint rather than recomputing them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from controlmm.errors import InputFileError
from controlmm.motion.skeleton import FEATURE_DIM

FEATURE_GROUPS: dict[str, slice] = {
    "root_rot_vel": slice(0, 1),
    "root_lin_vel": slice(1, 3),
    "root_y": slice(3, 4),
    "ric": slice(4, 67),
    "rot": slice(67, 193),
    "vel": slice(193, 259),
    "contacts": slice(259, 263),
}
"""The seven feature groups of the 263-d vector."""


def group_std(features: np.ndarray, eps: float = 1e-8) -> tuple[np.ndarray, np.ndarray]:
    """Mean and group-mean std of features (N, 263), as HumanML3D's ``cal_mean_variance``."""
    mean = features.mean(axis=0)
    std = features.std(axis=0)
    for sl in FEATURE_GROUPS.values():
        std[sl] = std[sl].mean()
    return mean.astype(np.float32), np.maximum(std, eps).astype(np.float32)


@dataclass(frozen=True)
class Normalizer:
    """Per-dimension mean and std, (263,) each; ``normalize(x) = (x - mean) / std``."""

    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self) -> None:
        for name in ("mean", "std"):
            arr = np.asarray(getattr(self, name), dtype=np.float32)
            if arr.shape != (FEATURE_DIM,) or not np.all(np.isfinite(arr)):
                raise InputFileError(f"{name} must be a finite ({FEATURE_DIM},) array; got shape {arr.shape}")
            object.__setattr__(self, name, arr)
        if np.any(self.std <= 0):
            raise InputFileError("std must be positive in every dimension")

    @classmethod
    def load(cls, mean_path: str | Path, std_path: str | Path) -> Normalizer:
        """Load from two ``.npy`` files (e.g. HumanML3D ``Mean.npy`` and ``Std.npy``)."""
        arrays = []
        for path in (mean_path, std_path):
            path = Path(path)
            if not path.is_file():
                raise InputFileError(f"statistics file '{path}' does not exist")
            try:
                arrays.append(np.load(path))
            except Exception as exc:  # noqa: BLE001 - any unreadable file is a user error
                raise InputFileError(f"cannot read '{path}': {exc}") from exc
        return cls(*arrays)

    def with_feat_bias(self, feat_bias: float = 5.0, times: int = 2) -> Normalizer:
        """Divide the std of dims 0-3 and 259-262 by ``feat_bias ** times`` (MoMask's quirk)."""
        std = self.std.copy()
        factor = feat_bias**times
        std[0:4] /= factor
        std[259:263] /= factor
        return Normalizer(self.mean, std)

    def normalize(self, x):
        """(..., 263) -> (..., 263); NumPy arrays or torch tensors."""
        mean, std = self._like(x)
        return (x - mean) / std

    def denormalize(self, x):
        """Inverse of :meth:`normalize`; NumPy arrays or torch tensors."""
        mean, std = self._like(x)
        return x * std + mean

    def _like(self, x):
        if isinstance(x, torch.Tensor):
            return (
                torch.as_tensor(self.mean, dtype=x.dtype, device=x.device),
                torch.as_tensor(self.std, dtype=x.dtype, device=x.device),
            )
        return self.mean, self.std
