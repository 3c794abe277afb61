"""Trajectory files for tracking stacks: LAFAN1-G1 CSV, MuJoCo-qpos CSV, BeyondMimic NPZ, GMR pickle.

``save_trajectory(traj, "out/walk", formats=("lafan1", "beyondmimic"))`` writes this project's
``walk.npz`` and ``walk.json`` (always: every tool here reads them) and each chosen format beside them:

===========  ======================  =================================================================
format       file                    content
===========  ======================  =================================================================
lafan1       ``walk.csv``            Unitree LAFAN1-G1 rows (also BeyondMimic's / mjlab's ``csv_to_npz``
                                     input): no header; root x y z (m), root quaternion **qx qy qz qw
                                     (xyzw)**, joint angles (rad) in MJCF order; the trajectory's rate
                                     (``--fps``, 50 by default; LAFAN1's own data is 30 fps, so tell
                                     ``csv_to_npz`` ``--input_fps``)
qpos         ``walk_qpos.csv``       raw MuJoCo ``qpos`` rows: no header; root x y z, root quaternion
                                     **qw qx qy qz (wxyz)**, joint angles in MJCF order; the
                                     trajectory's rate (the layout of Kimodo's G1 CSV; for a robot
                                     file the retargeter edits as it reads it, the free-joint rows,
                                     the NPZ's ``qpos_floating``: :mod:`retarget.file_layout`)
beyondmimic  ``walk_beyondmimic.npz``  BeyondMimic's motion file at **50 fps** (resampled: cubic splines
                                     for positions and joints, SLERP for the root): ``fps`` ([50]),
                                     ``joint_pos``, ``joint_vel`` (T, nj; MJCF joint order, as mjlab),
                                     ``body_pos_w`` (T, B, 3), ``body_quat_w`` (T, B, 4, **wxyz**),
                                     ``body_lin_vel_w``, ``body_ang_vel_w`` (T, B, 3, world frame), plus
                                     ``joint_names`` and ``body_names`` (B bodies in MJCF order, the
                                     floating base first); float32 like the original
gmr          ``walk.pkl``            GMR's robot-motion pickle: ``fps`` (the trajectory's), ``root_pos``
                                     (T, 3), ``root_rot`` (T, 4, **xyzw**), ``dof_pos`` (T, nj; MJCF
                                     order), ``local_body_pos`` (T, B, 3: forward kinematics with the
                                     root at the origin, unrotated), ``link_body_list`` (B body names)
===========  ======================  =================================================================

:func:`read_export` reads each of them back to ``(qpos (T, nq) wxyz, fps)``; the GMR pickle is read
with :func:`controlmm.files.load_pickle`, which refuses anything but plain data (a pickle can run
code as it loads).
"""

from __future__ import annotations

import pickle
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from controlmm.atomic import atomic_open, atomic_path
from controlmm.errors import ControlMMError, InputFileError, ShapeError
from controlmm.files import input_file, load_array, load_pickle
from retarget.metrics import replay
from retarget.resample import resample_qpos
from retarget.trajectory import RobotTrajectory

BEYONDMIMIC_FPS = 50
"""BeyondMimic's motion files are at 50 fps (its ``csv_to_npz`` default)."""


@dataclass(frozen=True)
class ExportFormat:
    """A trajectory file format: where it goes (``prefix + tail``), its quaternion order and rate."""

    name: str
    tail: str
    quaternion: str
    rate: str
    what: str


EXPORT_FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat("lafan1", ".csv", "xyzw", "the trajectory's", "Unitree LAFAN1-G1 / BeyondMimic CSV"),
        ExportFormat("qpos", "_qpos.csv", "wxyz", "the trajectory's", "MuJoCo qpos CSV"),
        ExportFormat(
            "beyondmimic", "_beyondmimic.npz", "wxyz", f"{BEYONDMIMIC_FPS} fps", "BeyondMimic training NPZ"
        ),
        ExportFormat("gmr", ".pkl", "xyzw", "the trajectory's", "GMR robot-motion pickle"),
    )
}
"""The export formats by name (``--format``)."""

DEFAULT_FORMATS: tuple[str, ...] = ("lafan1",)
"""What ``retarget`` and ``plan`` write beside the NPZ and JSON unless told otherwise."""


def parse_formats(text: str | Iterable[str]) -> tuple[str, ...]:
    """Export format names from ``"lafan1,gmr"`` (or a list); ``all`` = every format; one-line errors."""
    names = [n.strip().lower() for n in (text.split(",") if isinstance(text, str) else text)]
    names = [n for n in names if n]
    if names == ["all"]:
        return tuple(EXPORT_FORMATS)
    unknown = [n for n in names if n not in EXPORT_FORMATS]
    if unknown or not names:
        raise ControlMMError(
            f"unknown export format '{unknown[0] if unknown else text}'; allowed: "
            f"{', '.join(EXPORT_FORMATS)} (comma-separated) or all"
        )
    return tuple(dict.fromkeys(names))


def export_paths(prefix: str | Path, formats: Sequence[str]) -> dict[str, Path]:
    """``{format: path}`` of the chosen formats for an output ``prefix`` (``out/walk``)."""
    prefix = _prefix(prefix)
    return {f: prefix.with_name(prefix.name + EXPORT_FORMATS[f].tail) for f in formats}


def output_paths(prefix: str | Path, formats: Sequence[str]) -> list[Path]:
    """Every file :func:`save_trajectory` writes: ``prefix.npz``, ``prefix.json`` and the formats'."""
    prefix = _prefix(prefix)
    base = [prefix.with_name(prefix.name + ext) for ext in (".npz", ".json")]
    return base + list(export_paths(prefix, formats).values())


def _prefix(prefix: str | Path) -> Path:
    prefix = Path(prefix)
    return prefix.with_suffix("") if prefix.suffix.lower() in (".csv", ".npz", ".json", ".pkl") else prefix


def save_trajectory(
    traj: RobotTrajectory, prefix: str | Path, formats: Sequence[str] = DEFAULT_FORMATS
) -> dict[str, Path]:
    """Write ``prefix.npz``, ``prefix.json`` and every format of ``formats``; return ``{name: path}``
    (``npz``, ``json`` and the format names)."""
    formats = parse_formats(formats)
    paths = traj.save(prefix, csv="lafan1" in formats)
    out: dict[str, Path] = {"npz": paths["npz"], "json": paths["json"]}
    for name, path in export_paths(prefix, formats).items():
        if name == "lafan1":
            out[name] = paths["csv"]
            continue
        WRITERS[name](traj, path)
        out[name] = path
    return out


# -- writers ---------------------------------------------------------------------------------------
def lafan1_rows(qpos: np.ndarray) -> np.ndarray:
    """LAFAN1-G1 / BeyondMimic CSV rows (T, nq) of MuJoCo qpos (T, nq; free joint first, root
    quaternion wxyz): root x y z, root quaternion qx qy qz qw (xyzw), joint angles in MJCF order."""
    return np.concatenate([qpos[:, 0:3], qpos[:, [4, 5, 6, 3]], qpos[:, 7:]], axis=1)


def write_lafan1_csv(qpos: np.ndarray, path: str | Path) -> None:
    """The LAFAN1-G1 / BeyondMimic CSV of MuJoCo qpos rows (:func:`lafan1_rows`): no header, 17
    significant digits, the rate is the caller's (``sim.physics`` writes 50 fps)."""
    with atomic_open(path, "w", encoding="ascii", newline="") as fh:
        np.savetxt(fh, lafan1_rows(qpos), fmt="%.17g", delimiter=",")


def write_qpos_csv(traj: RobotTrajectory, path: str | Path) -> None:
    """MuJoCo qpos rows (root quaternion wxyz), no header, 17 significant digits."""
    with atomic_open(path, "w", encoding="ascii", newline="") as fh:
        np.savetxt(fh, traj.qpos, fmt="%.17g", delimiter=",")


def beyondmimic_arrays(traj: RobotTrajectory) -> dict[str, np.ndarray]:
    """BeyondMimic's motion arrays of ``traj`` at 50 fps (see the module docstring)."""
    robot = traj.robot_model()
    qpos = traj.qpos
    if abs(traj.fps - BEYONDMIMIC_FPS) > 1e-9:
        qpos = resample_qpos(qpos, traj.fps, BEYONDMIMIC_FPS, robot.lower, robot.upper)
    dt = 1.0 / BEYONDMIMIC_FPS
    rep = replay(robot.model, qpos)
    body_pos, body_quat = rep.xpos[:, 1:], rep.xquat[:, 1:]
    joint_pos = qpos[:, 7:]
    return {
        "fps": np.array([BEYONDMIMIC_FPS], dtype=np.int64),
        "joint_pos": joint_pos.astype(np.float32),
        "joint_vel": _derivative(joint_pos, dt).astype(np.float32),
        "body_pos_w": body_pos.astype(np.float32),
        "body_quat_w": body_quat.astype(np.float32),
        "body_lin_vel_w": _derivative(body_pos, dt).astype(np.float32),
        "body_ang_vel_w": world_angular_velocity(body_quat, dt).astype(np.float32),
        "joint_names": np.array(traj.joint_names),
        "body_names": np.array(robot.body_names),
    }


def write_beyondmimic_npz(traj: RobotTrajectory, path: str | Path) -> None:
    """BeyondMimic's training NPZ at 50 fps."""
    arrays = beyondmimic_arrays(traj)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            # allow_pickle named, as in controlmm.motion.io, so that no array of ``arrays`` takes the keyword.
            np.savez(fh, allow_pickle=False, **arrays)


def gmr_dict(traj: RobotTrajectory) -> dict[str, Any]:
    """GMR's robot-motion dict of ``traj`` (numpy arrays, the body names as a list of str)."""
    robot = traj.robot_model()
    local = traj.qpos.copy()
    local[:, 0:3] = 0.0
    local[:, 3:7] = (1.0, 0.0, 0.0, 0.0)
    return {
        "fps": float(traj.fps),
        "root_pos": traj.qpos[:, 0:3].copy(),
        "root_rot": traj.qpos[:, [4, 5, 6, 3]].copy(),
        "dof_pos": traj.qpos[:, 7:].copy(),
        "local_body_pos": replay(robot.model, local).xpos[:, 1:].copy(),
        "link_body_list": list(robot.body_names),
    }


def write_gmr_pickle(traj: RobotTrajectory, path: str | Path) -> None:
    """GMR's robot-motion pickle (protocol 4: readable by Python 3.4 and later)."""
    with atomic_open(path, "wb") as fh:
        pickle.dump(gmr_dict(traj), fh, protocol=4)


WRITERS = {"qpos": write_qpos_csv, "beyondmimic": write_beyondmimic_npz, "gmr": write_gmr_pickle}


def _derivative(values: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along time (one-sided at the ends), (T, ...); zeros for one frame."""
    if len(values) < 2:
        return np.zeros_like(values)
    return np.gradient(values, dt, axis=0)


def world_angular_velocity(quat_wxyz: np.ndarray, dt: float) -> np.ndarray:
    """World-frame angular velocities (T, B, 3) of body orientations (T, B, 4, wxyz) by central
    differences of the rotations: rotvec(R(t+1) R(t-1)^T) / (2 dt), one-sided at the ends."""
    t, b = quat_wxyz.shape[:2]
    if t < 2:
        return np.zeros((t, b, 3))
    rot = Rotation.from_quat(quat_wxyz.reshape(-1, 4)[:, [1, 2, 3, 0]])
    mats = rot.as_matrix().reshape(t, b, 3, 3)
    after = np.concatenate([mats[1:], mats[-1:]])
    before = np.concatenate([mats[:1], mats[:-1]])
    steps = np.full(t, 2.0)
    steps[0] = steps[-1] = 1.0
    delta = np.einsum("tbij,tbkj->tbik", after, before)
    rotvec = Rotation.from_matrix(delta.reshape(-1, 3, 3)).as_rotvec().reshape(t, b, 3)
    return rotvec / (steps[:, None, None] * dt)


# -- readers ---------------------------------------------------------------------------------------
def read_export(
    path: str | Path, fmt: str | None = None, fps: float | None = None
) -> tuple[np.ndarray, float]:
    """``(qpos (T, nq) wxyz, fps)`` of an exported file; ``fmt`` defaults to the file name's format.

    The CSV formats carry no rate: ``fps`` is required for them (and overrides the others').
    """
    path = input_file(path, "trajectory file")
    fmt = fmt or _format_of(path)
    if fmt in ("lafan1", "qpos"):
        if fps is None:
            raise InputFileError(f"'{path}' is a CSV, which has no frame rate: pass the fps")
        return read_csv_qpos(path, "xyzw" if fmt == "lafan1" else "wxyz"), float(fps)
    if fmt == "beyondmimic":
        data = load_array(path, "trajectory file")
        if not isinstance(data, dict):
            raise InputFileError(f"'{path}' is not a BeyondMimic NPZ (it is a single array)")
        qpos, rate = beyondmimic_qpos(data, str(path))
        return qpos, float(fps or rate)
    if fmt == "gmr":
        qpos, rate = read_gmr_pickle(path)
        return qpos, float(fps or rate)
    raise ControlMMError(f"unknown export format '{fmt}'; allowed: {', '.join(EXPORT_FORMATS)}")


def _format_of(path: Path) -> str:
    name = path.name.lower()
    for fmt in ("qpos", "beyondmimic", "gmr", "lafan1"):
        if name.endswith(EXPORT_FORMATS[fmt].tail):
            return fmt
    raise InputFileError(f"cannot tell the format of '{path}'; name it (lafan1, qpos, beyondmimic, gmr)")


def read_csv_qpos(path: str | Path, quaternion: str = "xyzw") -> np.ndarray:
    """qpos (T, nq) wxyz from a headerless CSV whose root quaternion is ``xyzw`` (LAFAN1) or ``wxyz``."""
    if quaternion not in ("xyzw", "wxyz"):
        raise ControlMMError(f"quaternion order must be xyzw or wxyz; got '{quaternion}'")
    try:
        rows = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise InputFileError(f"'{path}' is not a numeric CSV without header ({exc})") from None
    if rows.shape[1] < 8:
        raise InputFileError(f"'{path}' has {rows.shape[1]} columns; expected root xyz, quaternion, joints")
    if quaternion == "wxyz":
        return rows
    return np.concatenate([rows[:, 0:3], rows[:, [6, 3, 4, 5]], rows[:, 7:]], axis=1)


def beyondmimic_qpos(data: dict[str, np.ndarray], where: str) -> tuple[np.ndarray, float]:
    """qpos (T, nq) wxyz and fps of BeyondMimic arrays: the root from the first body's pose
    (``body_pos_w[:, 0]``, ``body_quat_w[:, 0]``), the joints from ``joint_pos`` (taken in MJCF order)."""
    needed = ("fps", "joint_pos", "body_pos_w", "body_quat_w")
    missing = [k for k in needed if k not in data]
    if missing:
        raise InputFileError(f"'{where}' is not a BeyondMimic NPZ: no {', '.join(missing)}")
    joint_pos = np.asarray(data["joint_pos"], dtype=np.float64)
    pos = np.asarray(data["body_pos_w"], dtype=np.float64)
    quat = np.asarray(data["body_quat_w"], dtype=np.float64)
    if joint_pos.ndim != 2 or pos.ndim != 3 or quat.ndim != 3 or not len(joint_pos) == len(pos) == len(quat):
        raise ShapeError(
            f"'{where}': joint_pos (T, nj), body_pos_w (T, B, 3), body_quat_w (T, B, 4) expected"
        )
    quat0 = quat[:, 0] / np.linalg.norm(quat[:, 0], axis=-1, keepdims=True)
    qpos = np.concatenate([pos[:, 0], quat0, joint_pos], axis=1)
    return qpos, float(np.asarray(data["fps"]).reshape(-1)[0])


def read_gmr_pickle(path: str | Path) -> tuple[np.ndarray, float]:
    """qpos (T, nq) wxyz and fps of a GMR robot-motion pickle, read with the restricted unpickler."""
    data = load_pickle(path, "GMR pickle")
    if not isinstance(data, dict):
        raise InputFileError(f"GMR pickle '{path}' holds a {type(data).__name__}, not a dict")
    missing = [k for k in ("fps", "root_pos", "root_rot", "dof_pos") if k not in data]
    if missing:
        raise InputFileError(f"GMR pickle '{path}' has no {', '.join(missing)}")
    try:
        root_pos = np.asarray(data["root_pos"], dtype=np.float64)
        root_rot = np.asarray(data["root_rot"], dtype=np.float64)
        dof_pos = np.asarray(data["dof_pos"], dtype=np.float64)
        fps = float(np.asarray(data["fps"]).reshape(-1)[0])
    except (TypeError, ValueError, IndexError) as exc:
        raise InputFileError(f"GMR pickle '{path}': {exc}") from None
    if root_pos.ndim != 2 or root_pos.shape[1] != 3 or root_rot.shape != (len(root_pos), 4):
        raise ShapeError(f"GMR pickle '{path}': root_pos (T, 3) and root_rot (T, 4) expected")
    if dof_pos.ndim != 2 or len(dof_pos) != len(root_pos):
        raise ShapeError(f"GMR pickle '{path}': dof_pos (T, ndof) expected; got {dof_pos.shape}")
    return np.concatenate([root_pos, root_rot[:, [3, 0, 1, 2]], dof_pos], axis=1), fps
