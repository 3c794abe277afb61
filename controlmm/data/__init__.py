"""Training data in the HumanML3D directory format (the real dataset or the project's corpus)."""

from controlmm.data.datasets import StepBatchSampler, TextMotionDataset, WindowDataset
from controlmm.data.humanml3d import Caption, HumanML3D, MotionSample

__all__ = ["Caption", "HumanML3D", "MotionSample", "StepBatchSampler", "TextMotionDataset", "WindowDataset"]
