"""Reading robot trajectories written by this project or by other retargeters.

Accepted files (what ``controlmm validate`` reads):

* ``.npz`` with ``qpos`` (T, nq; MuJoCo order, root quaternion **wxyz**) and ``fps``: this
  project's ``robot.npz``, holosoma/OmniRetarget-style files and anything alike;
* a BeyondMimic training ``.npz`` (``joint_pos``, ``body_pos_w``, ``body_quat_w``, ``fps``): the root
  from the first body's pose, the joints in MJCF order (as this project's and mjlab's files);
* ``.csv`` in the Unitree LAFAN1-G1 / BeyondMimic / mjlab row layout: no header, one row per
  frame, root x, y, z, root quaternion **qx, qy, qz, qw** (xyzw), then the joints in MJCF
  order; or raw MuJoCo qpos rows (root quaternion **wxyz**) with ``quaternion="wxyz"``. A CSV
  carries no rate: pass ``fps`` (LAFAN1 data is 30 fps);
* ``.pkl``: GMR's robot-motion pickle (``fps``, ``root_pos``, ``root_rot`` xyzw, ``dof_pos``), read
  by a restricted unpickler that builds numpy arrays and builtin containers only
  (:func:`controlmm.files.load_pickle`: a pickle can run code as it loads).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controlmm.errors import InputFileError, ShapeError
from controlmm.files import input_file, load_array
from controlmm.motion.container import check_finite
from retarget.exports import beyondmimic_qpos, read_csv_qpos, read_gmr_pickle

TRAJECTORY_SUFFIXES = (".npz", ".csv", ".pkl")


def load_qpos(
    path: str | Path, fps: float | None = None, quaternion: str = "xyzw"
) -> tuple[np.ndarray, float, str | None]:
    """Return ``(qpos (T, nq) wxyz, fps, robot name or None)`` from a trajectory file.

    ``fps`` overrides the file's rate (and is required for a ``.csv``); ``quaternion`` is the root
    quaternion order of a ``.csv`` (``xyzw``: LAFAN1-G1; ``wxyz``: raw MuJoCo qpos rows).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in TRAJECTORY_SUFFIXES:
        allowed = ", ".join(TRAJECTORY_SUFFIXES)
        raise InputFileError(f"unknown trajectory format '{path.suffix or path.name}'; allowed: {allowed}")
    path = input_file(path, "trajectory file")
    robot: str | None = None
    if suffix == ".csv":
        if fps is None:
            raise InputFileError(
                f"'{path}' is a CSV, which has no frame rate: pass --fps (LAFAN1 data is 30)"
            )
        qpos, rate = read_csv_qpos(path, quaternion), float(fps)
    elif suffix == ".pkl":
        qpos, file_rate = read_gmr_pickle(path)
        rate = float(fps) if fps is not None else file_rate
    else:
        data = load_array(path, "trajectory file")
        if isinstance(data, dict) and "qpos" not in data and "joint_pos" in data:
            qpos, file_rate = beyondmimic_qpos(data, str(path))
            return _checked(qpos, path), float(fps) if fps is not None else file_rate, None
        if not isinstance(data, dict) or "qpos" not in data:
            found = ", ".join(data) if isinstance(data, dict) else "a single array"
            raise InputFileError(f"'{path}' has no 'qpos' array; found: {found or 'none'}")
        try:
            # a robot file whose joints the retargeter changed: the rows it checks against
            # (retarget.file_layout; "qpos" is then the file's own layout)
            qpos = np.asarray(data["qpos_floating" if "qpos_floating" in data else "qpos"], dtype=np.float64)
            file_fps = float(np.asarray(data["fps"]).reshape(-1)[0]) if "fps" in data else None
        except (ValueError, TypeError, IndexError) as exc:
            raise InputFileError(f"cannot read '{path}': {exc}") from None
        given = fps if fps is not None else file_fps
        robot = str(data["robot"]) if "robot" in data else None
        if given is None:
            raise InputFileError(f"'{path}' has no 'fps' entry: pass --fps")
        rate = float(given)
    return _checked(qpos, path), rate, robot


def _checked(qpos: np.ndarray, path: Path) -> np.ndarray:
    if qpos.ndim != 2 or len(qpos) < 1:
        raise ShapeError(f"trajectory file '{path}': qpos must be (T, nq) with T >= 1; got {qpos.shape}")
    try:
        check_finite(qpos, "qpos")
    except ShapeError as exc:
        raise ShapeError(f"trajectory file '{path}': {exc}") from None
    return qpos
