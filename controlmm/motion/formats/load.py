"""Recorded motion of other skeletons -> the HumanML3D 22-joint :class:`~controlmm.motion.Motion`.

:func:`import_bvh` and :func:`import_positions` take a source skeleton's positions, pick the 22 SMPL
joints (by naming family, SMPL layout or mapping file), bring them to metres and Y up
(:mod:`~controlmm.motion.formats.conventions`) and run HumanML3D's processing
(:meth:`Motion.from_joints`: resampled to 20 fps, the reference skeleton's bone lengths with the
root path scaled by the leg-length ratio, floor at y = 0, starting at the origin facing +Z). The
motion's ``metadata["import"]`` records what was found: format, skeleton, up axis, unit, source
rate and frames, and the body size (``joint_height_m``: ankle to head joint along the bones).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.errors import ControlMMError, InputFileError, ShapeError
from controlmm.motion.container import Motion, check_finite
from controlmm.motion.formats.arrays import PositionArray
from controlmm.motion.formats.bvh_import import BvhAnimation, bvh_to_smpl22
from controlmm.motion.formats.conventions import UP_AXES, parse_units, to_y_up_metres
from controlmm.motion.formats.naming import SkeletonMap, detect_family, load_skeleton_map, unmapped_error
from controlmm.motion.formats.smpl import smpl_body_joints
from controlmm.motion.skeleton import FPS

SOURCE_FPS_RANGE = (1.0, 1000.0)


@dataclass(frozen=True)
class ImportOptions:
    """What the caller declares about a recorded motion (None: read from the file or detected).

    Attributes:
        up: ``"y"`` or ``"z"``: the file's up axis.
        fps: the file's frame rate (overrides what the file says).
        mapping: a mapping file (path) or :class:`SkeletonMap` for a skeleton of other names.
        units: the file's length unit (``m``, ``cm``, ``mm``, ``in``, ``cmu``) or metres per unit.
    """

    up: str | None = None
    fps: float | None = None
    mapping: str | Path | SkeletonMap | None = None
    units: str | float | None = None

    def __post_init__(self) -> None:
        if self.up is not None and self.up not in UP_AXES:
            raise ControlMMError(f"unknown up axis '{self.up}'; allowed: {', '.join(UP_AXES)}")
        if self.fps is not None:
            lo, hi = SOURCE_FPS_RANGE
            if not (np.isfinite(self.fps) and lo <= self.fps <= hi):
                raise ControlMMError(f"source fps {self.fps} is out of range; allowed {lo:g} to {hi:g}")
        if self.units is not None:
            parse_units(self.units)

    @property
    def empty(self) -> bool:
        return self.up is None and self.fps is None and self.mapping is None and self.units is None

    def skeleton_map(self) -> SkeletonMap | None:
        if self.mapping is None or isinstance(self.mapping, SkeletonMap):
            return self.mapping
        return load_skeleton_map(self.mapping)


def import_bvh(anim: BvhAnimation, path: Path, options: ImportOptions) -> Motion:
    """A parsed BVH of any naming family -> Motion (units detected from the skeleton's size)."""
    what = f"BVH file '{path}'"
    mapping = options.skeleton_map()
    joints, used = bvh_to_smpl22(anim, what, mapping)
    info = {"format": "bvh", "skeleton": used.name}
    return _finish(joints, what, path, options, used, anim.fps, info, detect_units=True)


def import_positions(array: PositionArray, path: Path, options: ImportOptions, fmt: str) -> Motion:
    """A joint-position array (SMPL-family layout, named joints, or a mapping file) -> Motion."""
    what = f"motion file '{path}'"
    mapping = options.skeleton_map()
    count = array.positions.shape[1]
    if mapping is not None:
        names = array.names or (list(mapping.joint_names) if mapping.joint_names else None)
        if names is None:
            raise InputFileError(
                f"{what}: the mapping '{mapping.name}' needs 'joint_names' (the array's column order) "
                "since the file names no joints"
            )
        if len(names) != count:
            raise ShapeError(f"{what}: {count} joints per frame, but the mapping names {len(names)} joints")
        missing = mapping.missing(names)
        if missing:
            raise InputFileError(
                f"{what}: the mapping '{mapping.name}' names unknown joints: {', '.join(missing)}"
            )
        joints, skeleton = mapping.apply(names, array.positions), mapping.name
    elif array.names is not None:
        family = detect_family(array.names, array.positions)
        if family is None:
            raise unmapped_error(what, array.names)
        joints, skeleton = family.apply(array.names, array.positions), family.name
    else:
        joints, skeleton = smpl_body_joints(array.positions, what)
        if array.layout is not None:
            skeleton = f"{array.layout} ({skeleton})"
    info = {"format": fmt, "skeleton": skeleton, "key": array.key}
    return _finish(joints, what, path, options, mapping, array.fps, info, detect_units=False)


def _finish(
    joints: np.ndarray,
    what: str,
    path: Path,
    options: ImportOptions,
    mapping: SkeletonMap | None,
    file_fps: float | None,
    info: dict[str, Any],
    detect_units: bool,
) -> Motion:
    try:
        check_finite(joints, "joint positions")
    except ShapeError as exc:
        raise ShapeError(f"{what}: {exc}") from None
    up = options.up or (mapping.up if mapping is not None else None)
    units = options.units if options.units is not None else (mapping.units if mapping is not None else None)
    metres, conv = to_y_up_metres(joints, what, up=up, units=units, detect_units=detect_units)
    fps = options.fps or file_fps or (mapping.fps if mapping is not None else None)
    if fps is None:
        raise InputFileError(f"{what} holds no frame rate: pass --source-fps N (e.g. 30, 60 or 120)")
    frames = int(np.floor((len(metres) - 1) / fps * FPS + 1e-9)) + 1
    if frames < 3:
        raise ShapeError(
            f"{what}: the clip is {len(metres)} frames at {fps:g} fps; at least 3 frames at {FPS} fps "
            f"({2 / FPS:g} s) are needed"
        )
    info.update({"source_fps": float(fps), "source_frames": int(len(joints)), **conv.to_dict()})
    return Motion.from_joints(metres, fps=float(fps), metadata={"source": str(path), "import": info})
