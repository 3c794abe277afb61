"""Reading robot trajectories written by this project or by other retargeters.

Accepted files (what ``controlmm validate`` reads):

* ``.npz`` with ``qpos`` (T, nq; MuJoCo order, root quaternion **wxyz**) and ``fps``: this
  project's ``robot.npz``, holosoma/OmniRetarget-style files and anything alike;
* ``.csv`` in the Unitree LAFAN1-G1 / BeyondMimic / mjlab row layout: no header, one row per
  frame, root x, y, z, root quaternion **qx, qy, qz, qw** (xyzw), then the joints in MJCF
  order. A CSV carries no rate: pass ``fps`` (LAFAN1 data is 30 fps).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controlmm.errors import InputFileError, ShapeError
from controlmm.files import input_file, load_array
from controlmm.motion.container import check_finite

TRAJECTORY_SUFFIXES = (".npz", ".csv")


def load_qpos(path: str | Path, fps: float | None = None) -> tuple[np.ndarray, float, str | None]:
    """Return ``(qpos (T, nq) wxyz, fps, robot name or None)`` from a trajectory file.

    ``fps`` overrides the file's rate (and is required for a ``.csv``).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in TRAJECTORY_SUFFIXES:
        raise InputFileError(f"unknown trajectory format '{path.suffix or path.name}'; allowed: .npz, .csv")
    path = input_file(path, "trajectory file")
    if suffix == ".csv":
        if fps is None:
            raise InputFileError(
                f"'{path}' is a CSV, which has no frame rate: pass --fps (LAFAN1 data is 30)"
            )
        try:
            rows = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise InputFileError(f"'{path}' is not a numeric CSV without header ({exc})") from None
        if rows.shape[1] < 8:
            raise InputFileError(
                f"'{path}' has {rows.shape[1]} columns; expected root xyz, qx qy qz qw, joints"
            )
        qpos = np.concatenate([rows[:, 0:3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)
        rate, robot = float(fps), None
    else:
        data = load_array(path, "trajectory file")
        if not isinstance(data, dict) or "qpos" not in data:
            found = ", ".join(data) if isinstance(data, dict) else "a single array"
            raise InputFileError(f"'{path}' has no 'qpos' array; found: {found or 'none'}")
        try:
            qpos = np.asarray(data["qpos"], dtype=np.float64)
            file_fps = float(np.asarray(data["fps"]).reshape(-1)[0]) if "fps" in data else None
        except (ValueError, TypeError, IndexError) as exc:
            raise InputFileError(f"cannot read '{path}': {exc}") from None
        given = fps if fps is not None else file_fps
        robot = str(data["robot"]) if "robot" in data else None
        if given is None:
            raise InputFileError(f"'{path}' has no 'fps' entry: pass --fps")
        rate = float(given)
    if qpos.ndim != 2 or len(qpos) < 1:
        raise ShapeError(f"trajectory file '{path}': qpos must be (T, nq) with T >= 1; got {qpos.shape}")
    try:
        check_finite(qpos, "qpos")
    except ShapeError as exc:
        raise ShapeError(f"trajectory file '{path}': {exc}") from None
    return qpos, float(rate), robot
