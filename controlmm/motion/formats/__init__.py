"""Recorded motion of other skeletons and files: BVH of any naming family, SMPL-family joint arrays.

``controlmm.motion.load_motion`` reads them all; this package holds the pieces:

- :mod:`~controlmm.motion.formats.naming` - naming families (LAFAN1, CMU, Mixamo, SMPL) and mapping files;
- :mod:`~controlmm.motion.formats.bvh_import` - any BVH file's joints and positions;
- :mod:`~controlmm.motion.formats.smpl` - SMPL / SMPL-H / SMPL-X position layouts;
- :mod:`~controlmm.motion.formats.arrays` - positions, rate and names in ``.npy`` / ``.npz`` / ``.pt``;
- :mod:`~controlmm.motion.formats.conventions` - up axis, units, left/right, body size;
- :mod:`~controlmm.motion.formats.load` - all of it -> the HumanML3D :class:`~controlmm.motion.Motion`.
"""

from controlmm.motion.formats.bvh_import import BvhAnimation, parse_bvh, read_bvh_file
from controlmm.motion.formats.conventions import UNITS, UP_AXES, Conventions
from controlmm.motion.formats.load import ImportOptions, import_bvh, import_positions
from controlmm.motion.formats.naming import (
    FAMILIES,
    SkeletonMap,
    detect_family,
    load_skeleton_map,
    skeleton_map_from_dict,
)
from controlmm.motion.formats.smpl import BODY_FIRST_LAYOUTS, smpl_body_joints

__all__ = [
    "BODY_FIRST_LAYOUTS",
    "FAMILIES",
    "UNITS",
    "UP_AXES",
    "BvhAnimation",
    "Conventions",
    "ImportOptions",
    "SkeletonMap",
    "detect_family",
    "import_bvh",
    "import_positions",
    "load_skeleton_map",
    "parse_bvh",
    "read_bvh_file",
    "skeleton_map_from_dict",
    "smpl_body_joints",
]
