"""Reading and writing motions: ``.npz`` (Motion), HumanML3D ``.npy``, ``.bvh``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import cast

import numpy as np

from controlmm.atomic import atomic_path
from controlmm.errors import InputFileError, ShapeError
from controlmm.files import input_file, load_array
from controlmm.motion.bvh import read_bvh, write_bvh
from controlmm.motion.container import Motion
from controlmm.motion.skeleton import FEATURE_DIM, FPS, NUM_JOINTS

READ_FORMATS = (".npz", ".npy", ".bvh")
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


def load_motion(path: str | Path) -> Motion:
    """Load a motion from ``.npz`` (this project's format), ``.npy`` (HumanML3D) or ``.bvh``.

    A HumanML3D ``.npy`` is told apart by shape: (T, 263) features or (T, 22, 3) joints.
    """
    suffix = _suffix(Path(path), READ_FORMATS)
    path = input_file(path, "motion file")
    try:
        return _load(path, suffix)
    except ShapeError as exc:
        raise ShapeError(f"motion file '{path}': {exc}") from None


def _load(path: Path, suffix: str) -> Motion:
    if suffix == ".bvh":
        joints, fps = read_bvh(path)
        return Motion(joints=joints, fps=fps, metadata={"source": str(path)})
    data = load_array(path, "motion file")
    if isinstance(data, np.ndarray):
        if suffix == ".npz":
            raise InputFileError(f"motion file '{path}' is not a valid NPZ file (it is an NPY array)")
        return _from_array(data, path)
    if suffix == ".npy":
        raise InputFileError(f"motion file '{path}' is not a valid NPY file (it is an NPZ archive)")
    if "joints" not in data:
        raise InputFileError(f"'{path}' has no 'joints' array; found keys: {', '.join(data) or 'none'}")
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


def _from_array(arr: np.ndarray, path: Path) -> Motion:
    if arr.ndim == 2 and arr.shape[1] == FEATURE_DIM:
        return Motion.from_features(arr, metadata={"source": str(path)})
    if arr.ndim == 3 and arr.shape[1:] == (NUM_JOINTS, 3):
        return Motion(joints=arr, fps=float(FPS), metadata={"source": str(path)})
    if arr.ndim == 2 and arr.shape[1] == NUM_JOINTS * 3:
        return Motion(joints=arr.reshape(-1, NUM_JOINTS, 3), fps=float(FPS), metadata={"source": str(path)})
    raise ShapeError(
        f"'{path}' holds an array of shape {arr.shape}; expected (T, {FEATURE_DIM}) features "
        f"or (T, {NUM_JOINTS}, 3) joints"
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
