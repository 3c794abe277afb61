"""Motion representation: the HumanML3D skeleton, features <-> joints, I/O, plots."""

from controlmm.motion.container import Motion, resample
from controlmm.motion.extract import joints_to_features
from controlmm.motion.io import check_output_format, load_motion, save_motion
from controlmm.motion.normalization import Normalizer
from controlmm.motion.plot import plot_motion, plot_or_animate
from controlmm.motion.recover import features_to_joints, features_to_joints_np

__all__ = [
    "Motion",
    "Normalizer",
    "check_output_format",
    "features_to_joints",
    "features_to_joints_np",
    "joints_to_features",
    "load_motion",
    "plot_motion",
    "plot_or_animate",
    "resample",
    "save_motion",
]
