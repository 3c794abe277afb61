"""Reading and writing motions: ``.npz`` (Motion), HumanML3D ``.npy``, ``.bvh``; recorded motion of
other skeletons (any BVH naming family, SMPL / SMPL-H / SMPL-X joint arrays in ``.npy``/``.npz``/``.pt``)
is read through :mod:`controlmm.motion.formats`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import cast

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.errors import InputFileError, ShapeError
from controlmm.files import input_file
from controlmm.motion.bvh import write_bvh
from controlmm.motion.container import Motion
from controlmm.motion.formats.arrays import position_array, read_arrays
from controlmm.motion.formats.bvh_import import read_bvh_file
from controlmm.motion.formats.conventions import PERSON_SIZE, detect_up
from controlmm.motion.formats.load import ImportOptions, import_bvh, import_positions
from controlmm.motion.formats.naming import SkeletonMap
from controlmm.motion.skeleton import FEATURE_DIM, FPS, JOINT_NAMES, NUM_JOINTS, body_size_ratio

READ_FORMATS = (".npz", ".npy", ".bvh", ".pt")
WRITE_FORMATS = (".npz", ".npy", ".bvh")
_NPZ_KEYS = {"joints", "fps", "features", "text", "metadata"}


def _suffix(path: Path, allowed: tuple[str, ...]) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise InputFileError(
            f"unknown motion format '{path.suffix or path.name}' for '{path}'; allowed: {', '.join(allowed)}"
        )
    return suffix


def check_output_format(path: str | Path) -> None:
    """Raise a one-line error unless ``path`` has a writable motion suffix."""
    _suffix(Path(path), WRITE_FORMATS)


def load_motion(
    path: str | Path,
    *,
    up: str | None = None,
    fps: float | None = None,
    mapping: str | Path | SkeletonMap | None = None,
    units: str | float | None = None,
) -> Motion:
    """Load a motion: this project's ``.npz``, HumanML3D ``.npy``, or recorded motion of another skeleton.

    This project's files load as they are: a Motion ``.npz``, a HumanML3D ``.npy`` told apart by shape
    ((T, 263) features or (T, 22, 3) joints) and an SMPL-22 ``.bvh``, when they are Y up and in metres.
    Everything else is imported (:mod:`controlmm.motion.formats`) into the HumanML3D Motion (metres,
    Y up, 20 fps, the reference skeleton, starting at the origin facing +Z, with features): a BVH of
    LAFAN1, CMU, Mixamo or SMPL naming, SMPL (24), SMPL-H (52) or SMPL-X (55) joint positions in
    ``.npy``/``.npz``/``.pt``, or any skeleton through a mapping file.

    Args:
        up: ``"y"`` or ``"z"``: the file's up axis (default: detected from the body).
        fps: the file's frame rate (default: the file's; required for a bare array).
        mapping: a mapping file (JSON) or :class:`~controlmm.motion.formats.SkeletonMap` for a
            skeleton of other names (docs/motion-formats.md).
        units: the file's length unit (``m``, ``cm``, ``mm``, ``in``, ``cmu``, or metres per unit);
            default: detected for BVH, metres for arrays.

    Giving any of these imports even a file of this project's formats.
    """
    suffix = _suffix(Path(path), READ_FORMATS)
    path = input_file(path, "motion file")
    options = ImportOptions(up=up, fps=fps, mapping=mapping, units=units)
    try:
        return _load(path, suffix, options)
    except ShapeError as exc:
        message = str(exc)
        raise ShapeError(message if str(path) in message else f"motion file '{path}': {message}") from None


def _load(path: Path, suffix: str, options: ImportOptions) -> Motion:
    if suffix == ".bvh":
        anim = read_bvh_file(path)
        if options.empty and all(n in anim.names for n in JOINT_NAMES):
            joints = anim.positions[:, [anim.names.index(n) for n in JOINT_NAMES]]
            if _native(joints):
                return Motion(joints=joints, fps=anim.fps, metadata={"source": str(path)})
        return import_bvh(anim, path, options)
    data = read_arrays(path, suffix)
    if suffix == ".npz" and "" in data:
        raise InputFileError(f"motion file '{path}' is not a valid NPZ file (it is an NPY array)")
    if suffix == ".npy" and "" not in data:
        raise InputFileError(f"motion file '{path}' is not a valid NPY file (it is an NPZ archive)")
    if suffix == ".npy" and isinstance(data.get(""), np.ndarray) and _is_features(data[""]):
        return Motion.from_features(data[""], metadata={"source": str(path)})
    if suffix == ".npz" and "" not in data and options.empty and _is_motion_npz(data):
        return _motion_npz(path, data)
    if suffix == ".npy" and options.empty:
        array = _joints22(data[""])
        if array is not None and _native(array):
            return Motion(joints=array, fps=float(FPS), metadata={"source": str(path)})
    return import_positions(position_array(data, f"motion file '{path}'"), path, options, suffix[1:])


def _is_features(arr: np.ndarray) -> bool:
    return arr.ndim == 2 and arr.shape[1] == FEATURE_DIM


def _joints22(arr: np.ndarray) -> np.ndarray | None:
    """``arr`` as (T, 22, 3) when it has that shape (or (T, 66)), else None."""
    if arr.ndim == 3 and arr.shape[1:] == (NUM_JOINTS, 3):
        return arr
    if arr.ndim == 2 and arr.shape[1] == NUM_JOINTS * 3:
        return arr.reshape(-1, NUM_JOINTS, 3)
    return None


def _native(joints: np.ndarray) -> bool:
    """Whether SMPL-22 joints (T, 22, 3) are in this project's convention: metres and Y up."""
    if not np.all(np.isfinite(joints)):
        return True  # the Motion's own check names the first bad frame
    ratio = body_size_ratio(joints)
    if not PERSON_SIZE[0] <= ratio <= PERSON_SIZE[1]:
        return False
    try:
        return detect_up(joints, "motion") == "y"
    except ShapeError:  # no clear up axis (a clip lying down): taken as it is, as before
        return True


def _is_motion_npz(data: dict) -> bool:
    joints = data.get("joints")
    if not isinstance(joints, np.ndarray) or joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        return False
    return "metadata" in data or "features" in data or _native(joints)


def _motion_npz(path: Path, data: dict) -> Motion:
    try:
        metadata = json.loads(str(data["metadata"])) if "metadata" in data else {}
    except json.JSONDecodeError:
        raise InputFileError(f"motion file '{path}': its 'metadata' is not valid JSON") from None
    return Motion(
        joints=data["joints"],
        fps=float(data["fps"]) if "fps" in data else float(FPS),
        features=data["features"] if "features" in data else None,
        text=str(data["text"]) if "text" in data else "",
        metadata=metadata,
        extras={k: v for k, v in data.items() if k not in _NPZ_KEYS},
    )


def save_motion(motion: Motion, path: str | Path, npy_kind: str = "features") -> None:
    """Save a motion atomically; the format follows the suffix.

    ``.npz`` keeps everything; ``.npy`` writes HumanML3D features (``npy_kind="features"``,
    computed if absent) or joints (``npy_kind="joints"``); ``.bvh`` writes the skeleton
    animation.
    """
    path = Path(path)
    suffix = _suffix(path, WRITE_FORMATS)
    if suffix == ".bvh":
        write_bvh(path, motion.joints, motion.fps)
        return
    if suffix == ".npy":
        if npy_kind not in ("features", "joints"):
            raise InputFileError(f"npy_kind must be 'features' or 'joints'; got '{npy_kind}'")
        if npy_kind == "features":
            arr = cast(np.ndarray, motion.with_features().features)  # with_features() always sets them
        else:
            arr = motion.joints
        with atomic_path(path) as tmp:
            np.save(tmp, arr)
        return
    arrays: dict[str, np.ndarray] = {
        "joints": motion.joints,
        "fps": np.asarray(motion.fps, dtype=np.float32),
        "text": np.asarray(motion.text),
        "metadata": np.asarray(json.dumps(motion.metadata)),
    }
    if motion.features is not None:
        arrays["features"] = motion.features
    for key, value in motion.extras.items():
        if key in arrays:
            raise InputFileError(f"extra array name '{key}' clashes with a reserved key")
        arrays[key] = np.asarray(value)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            # allow_pickle: numpy's default, named so that no array of ``arrays`` can take the keyword.
            np.savez_compressed(fh, allow_pickle=True, **arrays)
