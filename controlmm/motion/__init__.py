"""Motion representation: the HumanML3D skeleton, features <-> joints, I/O, plots."""

from controlmm.motion.container import Motion, resample
from controlmm.motion.extract import joints_to_features
from controlmm.motion.io import load_motion, save_motion
from controlmm.motion.normalization import Normalizer
from controlmm.motion.recover import features_to_joints, features_to_joints_np

__all__ = [
    "Motion",
    "Normalizer",
    "features_to_joints",
    "features_to_joints_np",
    "joints_to_features",
    "load_motion",
    "resample",
    "save_motion",
]
