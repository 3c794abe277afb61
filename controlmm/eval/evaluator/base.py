"""What every text-motion evaluator offers, and the helpers shared by the implementations.

An evaluator maps captions and motions to embeddings in one space (``embed_texts``,
``embed_motions``); the quality metrics (:mod:`controlmm.eval.metrics`) only ever see those
embeddings. Two implementations: the project's own (:mod:`.model`, trained with ``controlmm train
evaluator``) and the official HumanML3D evaluator (:mod:`.official`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import torch

from controlmm.data.humanml3d import Caption
from controlmm.errors import ShapeError
from controlmm.motion.container import Motion
from controlmm.motion.extract import joints_to_features
from controlmm.motion.normalization import Normalizer
from controlmm.motion.skeleton import FEATURE_DIM, MAX_FRAMES

MotionLike = Motion | np.ndarray
"""A Motion (features or joints) or a (T, 263) feature array, not normalised."""
TextLike = str | Caption
"""A caption string, or a HumanML3D caption with its ``.text`` and ``.tokens`` ("word/POS" tokens)."""


@runtime_checkable
class Evaluator(Protocol):
    """A text encoder and a motion encoder into a shared embedding space.

    Attributes:
        name: a short description for tables ("controlmm evaluator (corpus-default)", "official HumanML3D").
        dim: embedding size.
    """

    name: str
    dim: int

    def embed_texts(self, captions: Sequence[TextLike], batch_size: int = 256) -> np.ndarray:
        """Captions -> (N, dim) float64 embeddings."""
        ...

    def embed_motions(self, motions: Sequence[MotionLike], batch_size: int = 256) -> np.ndarray:
        """Motions (raw HumanML3D features, 20 fps, up to 196 frames) -> (N, dim) float64 embeddings."""
        ...


def caption_text(caption: TextLike) -> str:
    return caption if isinstance(caption, str) else str(caption.text)


def motion_features(motion: MotionLike) -> np.ndarray:
    """(T, 263) float32 features of a Motion or an array; joints-only motions are processed first."""
    if not isinstance(motion, Motion):
        features = np.asarray(motion, dtype=np.float32)
    elif motion.features is not None:
        features = np.asarray(motion.features, dtype=np.float32)
    else:  # a Motion without features: HumanML3D processing of its joints (T-1 frames)
        features = np.asarray(joints_to_features(motion.joints)[0], dtype=np.float32)
    if features.ndim != 2 or features.shape[1] != FEATURE_DIM:
        raise ShapeError(f"motion features must have shape (T, {FEATURE_DIM}); got {features.shape}")
    if not np.all(np.isfinite(features)):
        raise ShapeError("motion features contain NaN/inf values")
    return features


def pad_normalized(
    motions: Sequence[MotionLike], normalizer: Normalizer, unit: int = 4, max_frames: int = MAX_FRAMES
) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalise motions and zero-pad them after normalisation (as the official eval loader).

    Motions longer than ``max_frames`` keep their first ``max_frames`` frames; shorter than ``unit``
    frames are an error. Returns (B, max_frames, 263) float32 and the frame counts (B,) int64.
    """
    feats = [motion_features(m)[:max_frames] for m in motions]
    batch = np.zeros((len(feats), max_frames, FEATURE_DIM), dtype=np.float32)
    for i, f in enumerate(feats):
        if len(f) < unit:
            raise ShapeError(f"motion #{i} has {len(f)} frames; the evaluator needs at least {unit}")
        batch[i, : len(f)] = normalizer.normalize(f)
    return torch.from_numpy(batch), torch.tensor([len(f) for f in feats], dtype=torch.long)
