"""Joint-position arrays in ``.npy``, ``.npz`` and ``.pt`` files: the positions, their rate and names.

* ``.npy``: one array, (T, J, 3) or (T, J*3).
* ``.npz``: the positions under one of :data:`POSITION_KEYS` (the first present wins), the rate
  under one of :data:`FPS_KEYS` (AMASS: ``mocap_framerate``), optional ``joint_names``.
* ``.pt``: a tensor like the ``.npy``, or a dict with the keys of the ``.npz``; read with
  ``torch.load(weights_only=True)`` (:func:`controlmm.files.load_torch`): only tensors and plain
  containers, never arbitrary pickled objects. A (T, 591) tensor is an InterMimic OMOMO clip
  (:mod:`controlmm.motion.formats.smpl`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from controlmm.errors import InputFileError, ShapeError
from controlmm.files import load_array, load_torch
from controlmm.motion.formats.smpl import INTERMIMIC_COLUMNS, INTERMIMIC_FPS, INTERMIMIC_WIDTH

POSITION_KEYS = ("joints", "global_joint_positions", "joint_positions", "positions", "jtr", "joints3d")
FPS_KEYS = ("fps", "mocap_framerate", "mocap_frame_rate", "frame_rate", "framerate")
NAME_KEYS = ("joint_names", "names")


@dataclass
class PositionArray:
    """Joint positions read from a file, in its own axes and units.

    Attributes:
        positions: (T, J, 3) float64.
        fps: the file's frame rate, or None when it has none.
        names: the joints' names when the file gives them, else None.
        layout: ``"intermimic"`` when recognised by its shape, else None (told by the joint count).
        key: the array's key in the file ("" for a bare array).
    """

    positions: np.ndarray
    fps: float | None
    names: list[str] | None
    layout: str | None
    key: str


def read_arrays(path: Path, suffix: str) -> dict[str, Any]:
    """``{key: value}`` of a ``.npy`` (key ``""``), ``.npz`` or ``.pt`` file, tensors as numpy arrays."""
    if suffix in (".npy", ".npz"):
        data = load_array(path, "motion file")
        return {"": data} if isinstance(data, np.ndarray) else dict(data)
    loaded = load_torch(path, "motion file", hint="expected a tensor of joint positions or a dict of tensors")
    if isinstance(loaded, dict):
        return {str(k): _plain(v) for k, v in loaded.items()}
    return {"": _plain(loaded)}


def _plain(value: Any) -> Any:
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().numpy()
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return np.asarray(value)
    return value


def position_array(data: dict[str, Any], what: str) -> PositionArray:
    """The positions, rate and names of a file's ``data`` (:func:`read_arrays`); one-line errors."""
    key = "" if "" in data else next((k for k in POSITION_KEYS if k in data), None)
    if key is None:
        raise InputFileError(
            f"{what} has no joint positions: expected one of the keys {', '.join(POSITION_KEYS)}; "
            f"found: {', '.join(data) or 'none'}"
        )
    raw = data[key]
    if not isinstance(raw, np.ndarray) or not np.issubdtype(raw.dtype, np.number):
        raise InputFileError(f"{what}: '{key or 'the array'}' is not a numeric array")
    arr = np.asarray(raw, dtype=np.float64)
    layout = None
    if arr.ndim == 2 and arr.shape[1] == INTERMIMIC_WIDTH:
        arr, layout = arr[:, INTERMIMIC_COLUMNS], "intermimic"
    if arr.ndim == 2 and arr.shape[1] % 3 == 0 and arr.shape[1] > 3:
        arr = arr.reshape(arr.shape[0], -1, 3)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1:
        raise ShapeError(f"{what}: positions must have shape (T, J, 3) or (T, J*3); got {raw.shape}")
    fps = _fps(data, what)
    if fps is None and layout == "intermimic":
        fps = INTERMIMIC_FPS
    names = next((data[k] for k in NAME_KEYS if k in data), None)
    if names is not None:
        names = [str(n) for n in np.asarray(names).reshape(-1)]
        if len(names) != arr.shape[1]:
            raise ShapeError(f"{what}: {len(names)} joint names for {arr.shape[1]} joints")
    return PositionArray(positions=arr, fps=fps, names=names, layout=layout, key=key)


def _fps(data: dict[str, Any], what: str) -> float | None:
    for k in FPS_KEYS:
        if k in data:
            try:
                value = float(np.asarray(data[k]).reshape(-1)[0])
            except (TypeError, ValueError, IndexError):
                raise InputFileError(f"{what}: '{k}' is not a number") from None
            if not (np.isfinite(value) and value > 0):
                raise InputFileError(f"{what}: '{k}' must be a positive frame rate; got {value}")
            return value
    return None
